//! A world-server process with one expected agent; the test plays agent 0 over iceoryx2.

use std::process::Command;
use std::time::{Duration, Instant};

use iceoryx2::prelude::{CallbackProgression, SignalHandlingMode};
use protocol::ipc::{RunNode, WakeEvent};
use protocol::wire::{HELLO_STEP, UavCommand};
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary, small_scenario_toml};

/// Steps of the test scenario: 2 s at T = 0.5 s.
const STEPS: u64 = 4;

#[test]
fn agent_receives_intact_frames_in_lockstep_and_the_world_cleans_up() {
    let t = TestRun::new("frames");
    let scenario = t.write("scenario.toml", &small_scenario_toml(2.0));
    let tag = t.run.tag();

    let mut world = ChildGuard::spawn(
        Command::new(binary("world-server"))
            .arg("--run-id")
            .arg(t.run.as_str())
            .arg("--scenario")
            .arg(&scenario)
            .args(["--agents", "0", "--start-timeout-ms", "60000"])
            .args(["--ack-timeout-ms", "30000"]),
    );

    let mut steps_seen = Vec::new();
    {
        let node = RunNode::new(
            &t.run,
            &RunNode::agent_name(0),
            SignalHandlingMode::Disabled,
        )
        .unwrap();
        let frames = node
            .open_cvs(0)
            .unwrap()
            .subscriber_builder()
            .create()
            .unwrap();
        let commands = node
            .open_cmd(0)
            .unwrap()
            .publisher_builder()
            .create()
            .unwrap();
        let wake_world = node
            .open_world_wake()
            .unwrap()
            .notifier_builder()
            .create()
            .unwrap();
        let wake_me = node
            .open_agent_wake(0)
            .unwrap()
            .listener_builder()
            .create()
            .unwrap();
        let waitset = node.waitset().unwrap();
        let _guard = waitset.attach_notification(&wake_me).unwrap();

        let send = |step: u64| {
            let cmd = UavCommand {
                run_tag: tag,
                step,
                uav: 0,
                has_yaw_ref: 0,
                yaw_ref_rad: 0.0,
                incarnation: 1,
            };
            commands.send_copy(cmd).unwrap();
            let _ = wake_world.notify_with_custom_event_id(WakeEvent::Command.id());
        };

        let deadline = Instant::now() + EXIT_TIMEOUT;
        let mut last_hello = None::<Instant>;
        let mut ended = false;
        while !ended && Instant::now() < deadline {
            if steps_seen.is_empty()
                && last_hello.is_none_or(|t| t.elapsed() > Duration::from_millis(200))
            {
                send(HELLO_STEP);
                last_hello = Some(Instant::now());
            }
            waitset
                .wait_and_process_once_with_timeout(
                    |_| {
                        let _ = wake_me.try_wait(|e| {
                            ended |= WakeEvent::from_id(e.id) == Some(WakeEvent::EndOfRun)
                        });
                        CallbackProgression::Continue
                    },
                    Duration::from_millis(100),
                )
                .unwrap();
            while let Some(sample) = frames.receive().unwrap() {
                let frame = sample.payload();
                let h = &frame.header;
                assert!(frame.is_well_formed(), "{h:?}");
                assert_eq!(h.checksum, frame.checksum(), "corrupted frame {}", h.step);
                assert_eq!((h.run_tag, h.uav, h.rows, h.cols), (tag, 0, 36, 48));
                assert_eq!(h.step, steps_seen.len() as u64, "frames out of order");
                assert!((h.time_s - h.step as f64 * 0.5).abs() < 1e-9);
                for b in frame.boxes() {
                    assert!(b.is_valid(h.rows, h.cols), "{b:?}");
                }
                steps_seen.push(h.step);
                send(h.step);
            }
            if !world.is_running() {
                break;
            }
        }
    }

    assert_eq!(steps_seen, (0..STEPS).collect::<Vec<_>>());
    let out = world
        .wait_timeout(EXIT_TIMEOUT)
        .expect("world-server did not exit after the last step");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "world-server failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // iceoryx2 keeps one persistent management segment per prefix by design; anything else
    // left behind would be a leak of the world or of this test's agent.
    let leftovers: Vec<_> = t
        .ipc_files()
        .into_iter()
        .filter(|p| p.starts_with("/dev/shm"))
        .filter(|p| !p.to_string_lossy().ends_with(".global_mgmt"))
        .collect();
    assert!(leftovers.is_empty(), "left in /dev/shm: {leftovers:?}");
}

#[test]
fn world_stops_cleanly_on_sigterm_while_waiting_for_agents() {
    let t = TestRun::new("sigterm");
    let scenario = t.write("scenario.toml", &small_scenario_toml(600.0));
    let mut world = ChildGuard::spawn(
        Command::new(binary("world-server"))
            .arg("--run-id")
            .arg(t.run.as_str())
            .arg("--scenario")
            .arg(&scenario)
            .args(["--agents", "0", "--start-timeout-ms", "600000"]),
    );
    // Wait until the world's node exists (it handles SIGTERM from its first wait on).
    let deadline = Instant::now() + EXIT_TIMEOUT;
    while !protocol::ipc::scan_nodes(&t.run, false)
        .map(|s| s.is_alive(RunNode::WORLD))
        .unwrap_or(false)
    {
        assert!(
            Instant::now() < deadline,
            "world-server never created its node"
        );
        assert!(world.is_running(), "world-server exited early");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(200));
    world.signal(libc::SIGTERM);
    let out = world
        .wait_timeout(EXIT_TIMEOUT)
        .expect("world-server ignored SIGTERM");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let leftovers: Vec<_> = t
        .ipc_files()
        .into_iter()
        .filter(|p| !p.to_string_lossy().ends_with(".global_mgmt"))
        .collect();
    assert!(leftovers.is_empty(), "left behind: {leftovers:?}");
}
