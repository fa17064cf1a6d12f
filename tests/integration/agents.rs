//! A world-server and real agent processes, without the orchestrator: the estimator exchange,
//! identity checks, bad peer messages and a lost world.

use std::process::Output;
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{SignalHandlingMode, WaitSet};
use protocol::ipc::{Ipc, RunNode, WakeEvent, WirePublisher, scan_nodes};
use protocol::wire::{HELLO_STEP, ObserverAck, TruthState, UavMask, WireHeader, WireKind, uav_bit};
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, follow, run_process, wait_until, world_server};

/// A small scenario with a camera large enough to see and identify cars.
fn scenario(duration_s: f64, uavs: u32) -> String {
    format!(
        "seed = 3\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 4\n\n[uavs]\ncount = {uavs}\n\n[camera]\nrows = 120\ncols = 160\n"
    )
}

fn agent(t: &TestRun, scenario: &std::path::Path, id: u32, extra: &[&str]) -> ChildGuard {
    ChildGuard::spawn(
        run_process("uav-agent", t, scenario)
            .arg("--id")
            .arg(id.to_string())
            .args(extra),
    )
}

fn finish(mut child: ChildGuard, what: &str) -> Output {
    child
        .wait_timeout(EXIT_TIMEOUT)
        .unwrap_or_else(|| panic!("{what} did not end within {EXIT_TIMEOUT:?}"))
}

fn report(out: &Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line).unwrap_or_else(|e| {
        panic!(
            "no JSON report ({e}) in {text:?}; stderr: {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn agent_alive(t: &TestRun, id: u32) -> bool {
    scan_nodes(&t.run, false).is_ok_and(|s| s.is_alive(&RunNode::agent_name(id)))
}

#[test]
fn two_agents_shrink_their_sets_and_agree_after_fusion() {
    let t = TestRun::new("two-agents");
    let file = t.write("scenario.toml", &scenario(30.0, 2));
    let w = world_server(&t, &file, "0,1", &[]);
    let a0 = agent(&t, &file, 0, &[]);
    let a1 = agent(&t, &file, 1, &[]);
    let (r0, r1) = (finish(a0, "agent 0"), finish(a1, "agent 1"));
    let wo = finish(w, "world-server");
    assert!(
        wo.status.success(),
        "world: {}",
        String::from_utf8_lossy(&wo.stderr)
    );
    let (r0, r1) = (report(&r0), report(&r1));
    let cells = 400 * 400; // 200 m at 0.5 m
    for r in [&r0, &r1] {
        assert_eq!(r["frames"], 60, "{r}");
        assert_eq!(r["estimates_received"], 60, "{r}");
        assert_eq!(r["end"], "EndOfRun");
        assert_eq!(r["final_step"], 59);
        let left = r["final_undetected_cells"].as_u64().unwrap();
        assert!(left < cells, "X̄ did not shrink: {left} of {cells}");
        assert!(r["decisions"].as_u64().unwrap() >= 10, "{r}");
    }
    assert_eq!(r0["final_undetected_digest"], r1["final_undetected_digest"]);
    assert_eq!(r0["final_undetected_cells"], r1["final_undetected_cells"]);
}

#[test]
fn an_agent_outside_the_fleet_is_refused() {
    let t = TestRun::new("outside");
    let file = t.write("scenario.toml", &scenario(5.0, 2));
    let out = finish(agent(&t, &file, 5, &[]), "agent 5");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("outside the fleet") && err.contains("2 UAVs"),
        "{err}"
    );
}

#[test]
fn a_second_agent_with_a_live_id_is_refused() {
    let t = TestRun::new("duplicate");
    let file = t.write("scenario.toml", &scenario(20.0, 1));
    let w = world_server(&t, &file, "0", &[]);
    let first = agent(&t, &file, 0, &[]);
    wait_until("agent 0 to be live", Duration::from_secs(30), || {
        agent_alive(&t, 0)
    });
    let out = finish(agent(&t, &file, 0, &[]), "second agent 0");
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("already live"), "{err}");
    // The first one is untouched and completes the run.
    let r = report(&finish(first, "agent 0"));
    assert_eq!(r["frames"], 40, "{r}");
    assert!(finish(w, "world-server").status.success());
}

/// Publishes one message on a wire service with the given header fields.
fn publish(publisher: &WirePublisher, header: WireHeader, bytes: &[u8]) {
    let mut sample = publisher
        .loan_slice_uninit(bytes.len())
        .expect("loan a sample");
    *sample.user_header_mut() = header;
    sample.write_from_slice(bytes).send().expect("send");
}

#[test]
fn bad_peer_messages_are_counted_and_dropped() {
    let t = TestRun::new("bad-peer");
    // Two UAVs in the scenario, but only agent 0 runs: the test speaks on UAV 1's services
    // from a node that is not an agent, so agent 0 never waits for it.
    let file = t.write("scenario.toml", &scenario(20.0, 2));
    let w = world_server(&t, &file, "0", &[]);
    let a0 = agent(&t, &file, 0, &[]);
    wait_until("agent 0 to be live", Duration::from_secs(30), || {
        agent_alive(&t, 0)
    });
    let node = RunNode::new(&t.run, "intruder", SignalHandlingMode::Disabled).unwrap();
    let estimates = node.open_estimate(1).unwrap();
    let est = RunNode::wire_publisher(&estimates, 1024).unwrap();
    let guidance = node.open_guidance().unwrap();
    let tok = RunNode::wire_publisher(&guidance, 1024).unwrap();
    let wake = node
        .open_agent_wake(0)
        .unwrap()
        .notifier_builder()
        .create()
        .unwrap();
    let good = |kind: WireKind, len: usize| WireHeader::new(kind, t.run.tag(), 1, 3, len as u32, 0);
    let garbage: Vec<u8> = (0..200u32).map(|i| (i * 37 % 251) as u8).collect();
    for _ in 0..10 {
        // Corrupted / truncated payloads with a valid header.
        publish(&est, good(WireKind::Estimate, garbage.len()), &garbage);
        publish(&est, good(WireKind::Estimate, 3), &garbage[..3]);
        // Another protocol version, another run, a header lying about the length or sender.
        publish(
            &est,
            WireHeader {
                version: 99,
                ..good(WireKind::Estimate, 8)
            },
            &garbage[..8],
        );
        publish(
            &est,
            WireHeader {
                run_tag: 1,
                ..good(WireKind::Estimate, 8)
            },
            &garbage[..8],
        );
        publish(&est, good(WireKind::Estimate, 100), &garbage[..8]);
        publish(
            &est,
            WireHeader {
                sender: 0,
                ..good(WireKind::Estimate, 8)
            },
            &garbage[..8],
        );
        // A corrupted token.
        publish(&tok, good(WireKind::Token, 50), &garbage[..50]);
        let _ = wake.notify_with_custom_event_id(WakeEvent::Estimate.id());
        std::thread::sleep(Duration::from_millis(100));
    }
    let r = report(&finish(a0, "agent 0"));
    assert!(finish(w, "world-server").status.success());
    assert_eq!(r["frames"], 40, "the agent went on: {r}");
    let dropped = &r["dropped"];
    for key in [
        "estimate:Malformed",
        "estimate:Version",
        "estimate:OtherRun",
        "estimate:Length",
        "estimate:Sender",
        "token:Malformed",
    ] {
        assert!(
            dropped[key].as_u64().unwrap_or(0) >= 1,
            "{key} not counted: {dropped}"
        );
    }
}

#[test]
fn agents_exit_with_a_clear_message_when_the_world_is_killed() {
    let t = TestRun::new("world-killed");
    // Far longer than the test: the world is killed while it steps, however fast it steps.
    let file = t.write("scenario.toml", &scenario(3600.0, 2));
    let w = world_server(&t, &file, "0,1", &[]);
    let timeout = ["--world-timeout-ms", "1500"];
    let a0 = agent(&t, &file, 0, &timeout);
    let a1 = agent(&t, &file, 1, &timeout);
    wait_until("both agents", Duration::from_secs(30), || {
        agent_alive(&t, 0) && agent_alive(&t, 1)
    });
    std::thread::sleep(Duration::from_secs(2));
    w.signal(libc::SIGKILL);
    for (a, name) in [(a0, "agent 0"), (a1, "agent 1")] {
        let out = finish(a, name);
        assert_eq!(out.status.code(), Some(1), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("world-server") && err.contains("gone"),
            "{name}: {err}"
        );
    }
    drop(w);
    // The dead world's resources are cleaned by whoever scans next; nothing stays alive.
    let scan = scan_nodes(&t.run, true).unwrap();
    assert!(scan.alive.is_empty(), "{scan:?}");
}

#[test]
fn a_killed_token_holder_is_skipped_and_the_survivors_process_every_step() {
    let t = TestRun::new("kill-holder");
    let file = t.write("scenario.toml", &scenario(30.0, 3));
    let w = world_server(&t, &file, "0,1,2", &[]);
    // A token wait far longer than the test: only noticing the holder's death ends the wait.
    let long_wait = ["--token-wait-ms", "120000"];
    let a0 = agent(&t, &file, 0, &long_wait);
    // Agent 1 sits on the token for a long time at every turn: it holds it when killed.
    let mut cmd = run_process("uav-agent", &t, &file);
    cmd.args(["--id", "1"])
        .env("SETFLEET_TEST_HOLD_TOKEN_MS", "60000");
    let a1 = ChildGuard::spawn(&mut cmd);
    let a2 = agent(&t, &file, 2, &long_wait);
    wait_until("agent 1 to hold the token", Duration::from_secs(60), || {
        std::fs::read_dir("/proc").is_ok() && agent_alive(&t, 1) && agent_alive(&t, 2)
    });
    // Round 0 starts at the first frame: agent 0 decides, then agent 1 takes the token and
    // sits on it. Give it time to get there, then kill it mid-turn.
    std::thread::sleep(Duration::from_secs(3));
    a1.signal(libc::SIGKILL);
    let (r0, r2) = (
        report(&finish(a0, "agent 0")),
        report(&finish(a2, "agent 2")),
    );
    assert!(finish(w, "world-server").status.success());
    drop(a1);
    let rounds = 60 / 6;
    for r in [&r0, &r2] {
        assert_eq!(r["frames"], 60, "a survivor missed steps: {r}");
        assert_eq!(r["decisions"], rounds, "a survivor missed a round: {r}");
    }
    // Agent 2 took over from the dead holder at once, without waiting out a timeout.
    assert_eq!(r2["token_timeouts"], 0, "{r2}");
}

#[test]
fn a_restarted_agent_rebuilds_its_sets_from_its_peers() {
    let t = TestRun::new("restart");
    let file = t.write("scenario.toml", &scenario(120.0, 2));
    // The test is the run's observer: the world waits for its ack of every step, so agent 1
    // is killed and restarted at step KILL_STEP however fast the run goes.
    const KILL_STEP: u64 = 20;
    let observer = PlayedObserver::join(&t);
    let mut w = ChildGuard::spawn(
        run_process("world-server", &t, &file)
            .args([
                "--agents",
                "0,1",
                "--wait-observer",
                "--start-timeout-ms",
                "60000",
            ])
            .args(["--ack-timeout-ms", "30000"]),
    );
    let a0 = agent(&t, &file, 0, &[]);
    let mut a1 = Some(agent(&t, &file, 1, &[]));
    let mut again = None;
    observer.follow(&mut w, |step| {
        if step != KILL_STEP {
            return 0;
        }
        let killed = a1.take().expect("agent 1 is killed once");
        killed.signal(libc::SIGKILL);
        drop(killed);
        wait_until("agent 1's death", Duration::from_secs(30), || {
            !agent_alive(&t, 1)
        });
        again = Some(agent(&t, &file, 1, &[]));
        wait_until("the new agent 1", Duration::from_secs(30), || {
            agent_alive(&t, 1)
        });
        // Restarted: the world waits for its hello before the next frame.
        uav_bit(1)
    });
    let again = again.expect("the run reached the kill step");
    let (r0, r1) = (
        report(&finish(a0, "agent 0")),
        report(&finish(again, "agent 1")),
    );
    assert!(finish(w, "world-server").status.success());
    let steps = 240;
    assert_eq!(r0["frames"], steps, "the survivor missed steps: {r0}");
    assert_eq!(
        r1["frames"],
        steps - KILL_STEP - 1,
        "restarted agent frames: {r1}"
    );
    assert_eq!(r1["end"], "EndOfRun");
    // After fusing its peer's estimates the newcomer holds the same X̄ as the survivor.
    assert_eq!(
        r0["final_undetected_digest"], r1["final_undetected_digest"],
        "{r0} {r1}"
    );
}

/// This test, playing the run's observer over iceoryx2.
struct PlayedObserver {
    tag: u64,
    truth: Subscriber<Ipc, TruthState, ()>,
    acks: Publisher<Ipc, ObserverAck, ()>,
    wake_world: Notifier<Ipc>,
    wake_me: Listener<Ipc>,
    waitset: WaitSet<Ipc>,
    // Last: the ports above close before the node.
    _node: RunNode,
}

impl PlayedObserver {
    fn join(t: &TestRun) -> PlayedObserver {
        let node = RunNode::new(&t.run, RunNode::OBSERVER, SignalHandlingMode::Disabled)
            .expect("observer node");
        let truth = node.open_truth().expect("truth service");
        let acks = node.open_observer_ack().expect("observer ack service");
        let wake_world = node.open_world_wake().expect("world wake service");
        let wake_me = node.open_observer_wake().expect("observer wake service");
        PlayedObserver {
            tag: t.run.tag(),
            truth: truth
                .subscriber_builder()
                .create()
                .expect("truth subscriber"),
            acks: acks.publisher_builder().create().expect("ack publisher"),
            wake_world: wake_world.notifier_builder().create().expect("notifier"),
            wake_me: wake_me.listener_builder().create().expect("listener"),
            waitset: node.waitset().expect("waitset"),
            _node: node,
        }
    }

    fn ack(&self, step: u64, restarted: UavMask) {
        let ack = ObserverAck {
            run_tag: self.tag,
            step,
            restarted,
        };
        self.acks.send_copy(ack).expect("ack sent");
        let _ = self
            .wake_world
            .notify_with_custom_event_id(WakeEvent::ObserverAck.id());
    }

    /// Says hello until the first truth, then acks every step with the agents `on_step`
    /// reports restarted at it, until the end of the run or the world's exit.
    fn follow(&self, world: &mut ChildGuard, mut on_step: impl FnMut(u64) -> UavMask) {
        let hello = || self.ack(HELLO_STEP, 0);
        follow(
            &self.waitset,
            &self.wake_me,
            &self.truth,
            world,
            hello,
            |truth| {
                let restarted = on_step(truth.step);
                self.ack(truth.step, restarted);
            },
        );
    }
}
