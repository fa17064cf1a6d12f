//! A world-server process with one expected agent; the test plays agent 0 over iceoryx2.

use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{SignalHandlingMode, WaitSet};
use protocol::frame::CvsFrame;
use protocol::ipc::{Ipc, RunNode, WakeEvent};
use protocol::scenario::Scenario;
use protocol::wire::{HELLO_STEP, UavCommand};
use tests::{
    ChildGuard, EXIT_TIMEOUT, TestRun, follow, run_process, small_scenario_toml, world_server,
};
use world_server::World;

/// Steps of the test scenario: 2 s at T = 0.5 s.
const STEPS: u64 = 4;

/// This test, playing agent 0: its node and ports over iceoryx2.
struct PlayedAgent {
    tag: u64,
    frames: Subscriber<Ipc, CvsFrame, ()>,
    commands: Publisher<Ipc, UavCommand, ()>,
    wake_world: Notifier<Ipc>,
    wake_me: Listener<Ipc>,
    waitset: WaitSet<Ipc>,
    // Last: the ports above close before the node.
    _node: RunNode,
}

impl PlayedAgent {
    fn join(t: &TestRun) -> PlayedAgent {
        let node = RunNode::new(
            &t.run,
            &RunNode::agent_name(0),
            SignalHandlingMode::Disabled,
        )
        .expect("agent node");
        let frames = node.open_cvs(0).expect("iceoryx2");
        let commands = node.open_cmd(0).expect("iceoryx2");
        let wake_world = node.open_world_wake().expect("iceoryx2");
        let wake_me = node.open_agent_wake(0).expect("iceoryx2");
        PlayedAgent {
            tag: t.run.tag(),
            frames: frames.subscriber_builder().create().expect("iceoryx2"),
            commands: commands.publisher_builder().create().expect("iceoryx2"),
            wake_world: wake_world.notifier_builder().create().expect("iceoryx2"),
            wake_me: wake_me.listener_builder().create().expect("iceoryx2"),
            waitset: node.waitset().expect("iceoryx2"),
            _node: node,
        }
    }

    /// Answers `step` (or says hello), with a yaw reference if given.
    fn send(&self, step: u64, yaw_ref: Option<f64>) {
        let cmd = UavCommand {
            run_tag: self.tag,
            step,
            uav: 0,
            has_yaw_ref: u32::from(yaw_ref.is_some()),
            yaw_ref_rad: yaw_ref.unwrap_or(0.0),
            incarnation: 1,
        };
        self.commands.send_copy(cmd).expect("iceoryx2");
        let _ = self
            .wake_world
            .notify_with_custom_event_id(WakeEvent::Command.id());
    }

    /// Says hello until the first frame, and hands every frame to `answer` (which must send
    /// its command), until the end of the run, the world's exit or the test's deadline.
    fn play(&self, world: &mut ChildGuard, answer: impl FnMut(&CvsFrame)) {
        let hello = || self.send(HELLO_STEP, None);
        follow(
            &self.waitset,
            &self.wake_me,
            &self.frames,
            world,
            hello,
            answer,
        );
    }
}

/// The world-server's exit: successful, no panic; its report (the JSON line on stdout).
fn world_exit(world: &mut ChildGuard) -> serde_json::Value {
    let out = world
        .wait_timeout(EXIT_TIMEOUT)
        .expect("world-server did not exit after the last step");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "world-server failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout.lines().last().expect("no report on stdout");
    serde_json::from_str(line).expect("the report is not JSON")
}

#[test]
fn agent_receives_intact_frames_in_lockstep_and_the_world_cleans_up() {
    let t = TestRun::new("frames");
    let scenario = t.write("scenario.toml", &small_scenario_toml(2.0));
    let tag = t.run.tag();
    let mut world = world_server(&t, &scenario, "0", &[]);

    let mut steps_seen = Vec::new();
    {
        let agent = PlayedAgent::join(&t);
        agent.play(&mut world, |frame| {
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
            agent.send(h.step, None);
        });
    }

    assert_eq!(steps_seen, (0..STEPS).collect::<Vec<_>>());
    world_exit(&mut world);
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

/// The world-server renders the next step's frames while it waits for acks, and keeps them
/// only when no ack changed a yaw reference. Every frame must be the one the world stepped
/// with the acked references renders, whether it was rendered ahead, dropped or not.
#[test]
fn frames_rendered_ahead_are_those_of_the_world_stepped_with_the_acked_yaw_references() {
    let t = TestRun::new("ahead");
    let toml = small_scenario_toml(6.0);
    let scenario = t.write("scenario.toml", &toml);
    let mut local = World::new(&Scenario::from_toml_str(&toml).unwrap()).unwrap();
    // Guidance every 6 steps (3 s): steps 2 and 7 are not guidance steps, so the world renders
    // ahead there and must drop what it rendered when the ack turns the UAV.
    let turns = [(2, 1.0), (7, -2.0)];
    let mut world = world_server(&t, &scenario, "0", &[]);
    let mut steps_seen = Vec::new();
    {
        let agent = PlayedAgent::join(&t);
        let mut expected = CvsFrame::new_boxed();
        agent.play(&mut world, |frame| {
            let k = frame.header.step;
            assert_eq!(k, local.step(), "frames out of order");
            local.render(0, agent.tag, &mut expected);
            let n = frame.pixel_count();
            assert_eq!(frame.header.checksum, expected.header.checksum, "step {k}");
            let bits = |f: &CvsFrame| f.depth[..n].iter().map(|d| d.to_bits()).collect::<Vec<_>>();
            assert!(bits(frame) == bits(&expected), "depth of step {k}");
            assert_eq!(
                frame.labels[..n],
                expected.labels[..n],
                "labels of step {k}"
            );
            assert_eq!(frame.boxes(), expected.boxes(), "boxes of step {k}");
            steps_seen.push(k);
            let turn = turns.iter().find(|(s, _)| *s == k).map(|(_, yaw)| *yaw);
            if let Some(yaw) = turn {
                local.set_yaw_ref(0, yaw);
            }
            local.advance();
            agent.send(k, turn);
        });
    }
    assert_eq!(steps_seen, (0..12).collect::<Vec<_>>());
    let report = world_exit(&mut world);
    let agent = &report["agents"][0];
    let ahead = agent["frames_ahead"].as_u64().unwrap();
    let dropped = agent["frames_ahead_dropped"].as_u64().unwrap();
    // Frames 2 to 11 are rendered before the previous step's ack is awaited, but for frame 7
    // (after the guidance step 6, whose acks may turn the UAVs); frames 3 and 8 are dropped
    // (the turns acked at steps 2 and 7), and the frames 1 and 7 rendered when published.
    assert_eq!((ahead, dropped), (7, 2), "{agent}");
}

#[test]
fn world_stops_cleanly_on_sigterm_while_waiting_for_agents() {
    let t = TestRun::new("sigterm");
    let scenario = t.write("scenario.toml", &small_scenario_toml(600.0));
    let mut world = ChildGuard::spawn(run_process("world-server", &t, &scenario).args([
        "--agents",
        "0",
        "--start-timeout-ms",
        "600000",
    ]));
    // Wait until the world's node exists (it handles SIGTERM from before that).
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
