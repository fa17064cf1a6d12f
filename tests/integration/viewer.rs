//! Seeing a run: `fleet run --record` read back with the `mcap` crate, `fleet run --live`
//! watched by a WebSocket client speaking Foxglove's protocol, `run.gif`, and the run's
//! iceoryx2 configuration for iceoryx2's own tools.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::{Duration, Instant};

use foxglove::Decode;
use foxglove::messages::{Grid, SceneUpdate};
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, fleet_run};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

/// The topics every recording has, with their schemas.
const TOPICS: [(&str, &str); 14] = [
    ("/tf", "foxglove.FrameTransforms"),
    ("/city", "foxglove.SceneUpdate"),
    ("/uavs", "foxglove.SceneUpdate"),
    ("/truth/cars", "foxglove.SceneUpdate"),
    ("/guidance/plans", "foxglove.SceneUpdate"),
    ("/sets/undetected", "foxglove.Grid"),
    ("/sets/obstacle_neighbourhood", "foxglove.Grid"),
    ("/sets/unseen", "foxglove.Grid"),
    ("/sets/explored", "foxglove.Grid"),
    ("/map/oem", "foxglove.Grid"),
    ("/camera/labels", "foxglove.CompressedImage"),
    ("/camera/depth", "foxglove.CompressedImage"),
    ("/camera/boxes", "foxglove.ImageAnnotations"),
    ("/metrics", "fleetmetrics.FleetMetrics"),
];
/// Topics written once per step.
const PER_STEP: [&str; 9] = [
    "/tf",
    "/uavs",
    "/truth/cars",
    "/guidance/plans",
    "/sets/undetected",
    "/sets/obstacle_neighbourhood",
    "/sets/unseen",
    "/sets/explored",
    "/metrics",
];

/// Two UAVs over a small region, with a camera large enough to identify cars.
fn scenario(duration_s: f64) -> String {
    format!(
        "seed = 3\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 4\n\n[uavs]\ncount = 2\n\n[camera]\nrows = 120\ncols = 160\n"
    )
}

/// One message of a recording.
struct Logged {
    topic: String,
    log_time: u64,
    data: Vec<u8>,
}

/// Every message of the recording, with the schema name of each topic.
fn read_recording(path: &Path) -> (Vec<Logged>, BTreeMap<String, String>) {
    let bytes = std::fs::read(path).expect("the recording");
    let mut messages = Vec::new();
    let mut schemas = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a readable message");
        let schema = m.channel.schema.as_ref().map(|s| s.name.clone());
        assert_eq!(
            m.channel.message_encoding, "protobuf",
            "{}",
            m.channel.topic
        );
        schemas.insert(m.channel.topic.clone(), schema.unwrap_or_default());
        messages.push(Logged {
            topic: m.channel.topic.clone(),
            log_time: m.log_time,
            data: m.data.into_owned(),
        });
    }
    (messages, schemas)
}

/// Whether ground point `(x, y)` falls on a cell of `grid` whose `value` is 1.
fn grid_holds(grid: &Grid, x: f64, y: f64) -> bool {
    let corner = grid
        .pose
        .as_ref()
        .and_then(|p| p.position.as_ref())
        .expect("pose");
    let cell = grid.cell_size.as_ref().expect("cell size");
    let (c, r) = ((x - corner.x) / cell.x, (y - corner.y) / cell.y);
    let rows = grid.data.len() as u32 / grid.row_stride;
    if c < 0.0 || r < 0.0 || c >= f64::from(grid.column_count) || r >= f64::from(rows) {
        return false;
    }
    let at = r as u32 * grid.row_stride + c as u32 * grid.cell_stride;
    grid.data[at as usize] == 1
}

#[test]
fn a_recording_holds_every_topic_at_every_step_and_shows_the_guarantee() {
    let t = TestRun::new("view-record");
    let file = t.write("scenario.toml", &scenario(20.0));
    let out_dir = t.dir.join("out");
    let recording = t.dir.join("run.mcap");
    let mut fleet = ChildGuard::spawn(&mut fleet_run(
        &t,
        &file,
        &out_dir,
        &[
            "--strict",
            "--record",
            recording.to_str().expect("utf-8"),
            "--show-uav",
            "1",
        ],
    ));
    let out = fleet.wait_timeout(EXIT_TIMEOUT).expect("fleet run ended");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let steps = 40;

    let (messages, schemas) = read_recording(&recording);
    for (topic, schema) in TOPICS {
        assert_eq!(
            schemas.get(topic).map(String::as_str),
            Some(schema),
            "{topic}"
        );
    }
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for m in &messages {
        *counts.entry(m.topic.as_str()).or_default() += 1;
    }
    for topic in PER_STEP {
        assert_eq!(counts.get(topic), Some(&steps), "{topic}: {counts:?}");
    }
    // The city every 5 s and UAV 1's camera every second of the 20 s (lockstep loses no
    // frame: the world sends the next one only once the observer acked this one).
    assert_eq!(counts.get("/city"), Some(&4), "{counts:?}");
    for topic in ["/camera/labels", "/camera/depth", "/camera/boxes"] {
        assert_eq!(counts.get(topic), Some(&20), "{topic}: {counts:?}");
    }
    let oem = counts.get("/map/oem").copied().unwrap_or_default();
    assert!((1..=4).contains(&oem), "/map/oem: {oem}");
    // Log times are simulated time: step k at k * 0.5 s.
    let times: BTreeSet<u64> = messages
        .iter()
        .filter(|m| m.topic == "/metrics")
        .map(|m| m.log_time)
        .collect();
    let expected: BTreeSet<u64> = (0..steps as u64).map(|k| k * 500_000_000).collect();
    assert_eq!(times, expected);
    // The images are PNGs from UAV 1's camera.
    let labels = messages
        .iter()
        .find(|m| m.topic == "/camera/labels")
        .expect("labels");
    let image = foxglove::messages::CompressedImage::decode(labels.data.as_slice()).expect("image");
    assert_eq!(
        (image.format.as_str(), image.frame_id.as_str()),
        ("png", "uav1/camera")
    );
    assert!(image.data.starts_with(b"\x89PNG"));

    // At every step, every true car lies in the shown sets: in its X_j once identified,
    // else in X̄, as the estimator guarantees.
    let at = |topic: &str, time: u64| {
        messages
            .iter()
            .find(|m| m.topic == topic && m.log_time == time)
            .map(|m| m.data.as_slice())
    };
    let mut identified = 0;
    for &time in &expected {
        let cars = SceneUpdate::decode(at("/truth/cars", time).expect("cars")).expect("cars");
        let entity = &cars.entities[0];
        assert_eq!(entity.cubes.len(), 4);
        let undetected = Grid::decode(at("/sets/undetected", time).expect("X̄")).expect("a grid");
        for (cube, text) in entity.cubes.iter().zip(&entity.texts) {
            let id = text.text.trim_start_matches("car ");
            let p = cube
                .pose
                .as_ref()
                .and_then(|p| p.position.as_ref())
                .expect("pose");
            let holds = match at(&format!("/sets/targets/{id}"), time) {
                Some(data) => {
                    identified += 1;
                    grid_holds(&Grid::decode(data).expect("X_j"), p.x, p.y)
                }
                None => grid_holds(&undetected, p.x, p.y),
            };
            assert!(holds, "car {id} outside its set at {time} ns");
        }
    }
    assert!(identified > 0, "no car was identified in the run");
    // run.gif is there with the other pictures, and the run's iceoryx2 configuration.
    let gif = std::fs::read(out_dir.join("run.gif")).expect("run.gif");
    assert!(gif.starts_with(b"GIF89a"));
    let config = std::fs::read_to_string(out_dir.join("config/iceoryx2.toml")).expect("config");
    assert!(
        config.contains(&format!("prefix = \"iox2_sf_{}_\"", t.run.as_str())),
        "{config}"
    );
}

/// A free loopback TCP port (the test binds it, reads it and lets it go).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

#[test]
fn a_live_view_advertises_the_topics_and_streams_the_steps() {
    let t = TestRun::new("view-live");
    let file = t.write("scenario.toml", &scenario(30.0));
    let port = free_port();
    let address = format!("127.0.0.1:{port}");
    let mut fleet = ChildGuard::spawn(&mut fleet_run(
        &t,
        &file,
        &t.dir.join("out"),
        &[
            "--strict",
            "--live",
            &address,
            "--mode",
            "realtime",
            "--speedup",
            "2",
        ],
    ));
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("a runtime");
    let (topics, times) = runtime.block_on(watch(&format!("ws://{address}")));
    for (topic, schema) in TOPICS {
        assert_eq!(
            topics.get(topic).map(String::as_str),
            Some(schema),
            "{topic}"
        );
    }
    // Steps arrive in order, on the world's clock (a step every 0.5 s of simulated time).
    assert!(times.len() >= 3, "only {} steps arrived", times.len());
    assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
    assert!(times.iter().all(|t| t % 500_000_000 == 0), "{times:?}");
    let out = fleet.wait_timeout(EXIT_TIMEOUT).expect("fleet run ended");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Connects to the live view as Foxglove does, gathers the advertised topics and their
/// schemas, subscribes to `/metrics` and returns the log times of the first steps received.
async fn watch(url: &str) -> (BTreeMap<String, String>, Vec<u64>) {
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut request = url.into_client_request().expect("a request");
    request.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.sdk.v1".parse().expect("a header"),
    );
    // The server listens once the observer started: retry until then.
    let mut socket = loop {
        match tokio_tungstenite::connect_async(request.clone()).await {
            Ok((socket, _)) => break socket,
            Err(e) => {
                assert!(Instant::now() < deadline, "cannot connect to {url}: {e}");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    };
    let mut topics = BTreeMap::new();
    let mut metrics_channel = None;
    let mut times = Vec::new();
    const SUBSCRIPTION: u32 = 7;
    while times.len() < 5 {
        let left = deadline.saturating_duration_since(Instant::now());
        let message = match tokio::time::timeout(left, socket.next()).await {
            Ok(Some(Ok(m))) => m,
            other => panic!("the live view ended early: {other:?}; topics {topics:?}"),
        };
        match message {
            Message::Text(text) => {
                let v: Value = serde_json::from_str(text.as_str()).expect("JSON");
                if v["op"] != "advertise" {
                    continue;
                }
                for channel in v["channels"].as_array().expect("channels") {
                    let topic = channel["topic"].as_str().expect("topic").to_owned();
                    let schema = channel["schemaName"].as_str().unwrap_or_default();
                    if topic == "/metrics" && metrics_channel.is_none() {
                        let id = channel["id"].as_u64().expect("id");
                        metrics_channel = Some(id);
                        let subscribe = json!({
                            "op": "subscribe",
                            "subscriptions": [{"id": SUBSCRIPTION, "channelId": id}],
                        });
                        socket
                            .send(Message::text(subscribe.to_string()))
                            .await
                            .expect("subscribed");
                    }
                    topics.insert(topic, schema.to_owned());
                }
            }
            // Message data: opcode 1, subscription id, log time, payload.
            Message::Binary(data) if data.first() == Some(&1) && data.len() >= 13 => {
                let subscription = u32::from_le_bytes(data[1..5].try_into().expect("4 bytes"));
                let time = u64::from_le_bytes(data[5..13].try_into().expect("8 bytes"));
                assert_eq!(subscription, SUBSCRIPTION);
                times.push(time);
            }
            _ => {}
        }
    }
    (topics, times)
}
