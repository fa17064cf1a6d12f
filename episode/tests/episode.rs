//! An episode against the fleet it runs: reproducible, its learners asked in token order or
//! at the round's start, refused and deferring answers left to the UAV's own planner, and the same run
//! whether stepped alone or among others over threads.

use episode::{Episode, EpisodeError, EpisodeSpec, Episodes};
use protocol::plan::{Answer, Steer};

/// A small run: 3 UAVs over a 100 m square, a small camera, 12 s (4 guidance rounds of the
/// paper's 3 s).
fn spec(seed: u64, learners: &[u32]) -> EpisodeSpec {
    EpisodeSpec {
        seed,
        uavs: Some(3),
        duration_s: Some(12.0),
        learners: learners.to_vec(),
        overrides: [
            "region.half_extent_m=50",
            "targets.count=3",
            "camera.rows=60",
            "camera.cols=80",
        ]
        .map(str::to_owned)
        .to_vec(),
        ..EpisodeSpec::default()
    }
}

fn turn(increment: f64) -> Answer {
    Answer {
        steer: Steer::Increments(vec![increment]),
        poses: Vec::new(),
        planner_ns: 0,
    }
}

/// Runs `episode` to its end, answering every request with `answer(uav, round)`; returns the
/// requests' bytes in order.
fn play(episode: &mut Episode, answer: impl Fn(u32, u64) -> Option<Answer>) -> Vec<Vec<u8>> {
    let mut asked = Vec::new();
    while episode.run().expect("run") {
        for request in episode.pending().to_vec() {
            asked.push(request.bytes.clone());
            let bytes = match answer(request.uav, request.step) {
                Some(a) => a.encode(request.step, request.uav),
                None => b"not an answer".to_vec(),
            };
            episode.answer(request.uav, &bytes).expect("answer");
        }
    }
    asked
}

#[test]
fn an_episode_is_reproducible_and_asks_each_learner_once_per_round() {
    let answer = |uav: u32, step: u64| {
        Some(turn(if (uav as u64 + step).is_multiple_of(2) {
            0.5
        } else {
            -0.5
        }))
    };
    let mut first = Episode::new(&spec(4, &[0, 2])).expect("episode");
    let asked = play(&mut first, answer);
    let mut again = Episode::new(&spec(4, &[0, 2])).expect("episode");
    assert_eq!(play(&mut again, answer), asked);
    assert_eq!(first.timeseries_csv(), again.timeseries_csv());
    // 12 s at 0.5 s per step, a round every 3 s: steps 0, 6, 12 and 18; two learners each.
    assert_eq!(first.scenario().steps_per_guidance(), 6);
    assert_eq!(asked.len(), 8);
    assert_eq!(first.series().len(), 24);
    assert_eq!(first.violations(), 0);
    let counts = first.counts();
    assert_eq!((counts.asked, counts.answered, counts.malformed), (8, 8, 0));
    assert!(first.finished() && !first.run().expect("ended"));
    // Other answers fly another run.
    let mut other = Episode::new(&spec(4, &[0, 2])).expect("episode");
    play(&mut other, |_, _| Some(turn(1.0)));
    assert_ne!(other.timeseries_csv(), first.timeseries_csv());
}

#[test]
fn refused_answers_leave_the_decision_to_the_uavs_own_planner() {
    // Learner 1 answering nothing usable flies as UAV 1 does with no learner at all.
    let mut refused = Episode::new(&spec(5, &[1])).expect("episode");
    play(&mut refused, |_, _| None);
    assert_eq!(refused.counts().malformed, 4);
    let mut none = Episode::new(&spec(5, &[])).expect("episode");
    assert!(!none.run().expect("no learner: to the end"));
    assert_eq!(refused.timeseries_csv(), none.timeseries_csv());
}

#[test]
fn deferring_answers_fly_the_uavs_own_planner_and_count_as_answered() {
    // Learner 1 deferring every decision flies as UAV 1 does with no learner; half the
    // rounds deferred and half turned fly another run.
    let defer = || Answer {
        steer: Steer::Defer,
        poses: Vec::new(),
        planner_ns: 0,
    };
    let mut deferring = Episode::new(&spec(5, &[1])).expect("episode");
    play(&mut deferring, |_, _| Some(defer()));
    let counts = deferring.counts();
    assert_eq!(
        (
            counts.asked,
            counts.answered,
            counts.deferred,
            counts.malformed
        ),
        (4, 4, 4, 0)
    );
    let mut none = Episode::new(&spec(5, &[])).expect("episode");
    assert!(!none.run().expect("no learner: to the end"));
    assert_eq!(deferring.timeseries_csv(), none.timeseries_csv());
    let mut mixed = Episode::new(&spec(5, &[1])).expect("episode");
    play(&mut mixed, |_, step| {
        Some(if step < 12 { defer() } else { turn(1.0) })
    });
    assert_eq!(mixed.counts().deferred, 2);
    assert_ne!(mixed.timeseries_csv(), none.timeseries_csv());
}

#[test]
fn requests_must_be_answered_and_only_pending_ones() {
    let mut episode = Episode::new(&spec(6, &[0])).expect("episode");
    assert!(matches!(
        episode.answer(0, &[]),
        Err(EpisodeError::NotAsked(0))
    ));
    assert!(episode.run().expect("asks"));
    assert!(matches!(episode.run(), Err(EpisodeError::Unanswered(0))));
    let pending = episode.pending()[0].clone();
    assert_eq!((pending.uav, pending.step), (0, 0));
    assert!(matches!(
        episode.answer(1, &[]),
        Err(EpisodeError::NotAsked(1))
    ));
}

#[test]
fn at_the_rounds_start_every_learner_is_asked_before_any_decides() {
    let mut s = spec(7, &[0, 1]);
    s.overrides
        .push("guidance.external_request=round_start".to_owned());
    let mut episode = Episode::new(&s).expect("episode");
    assert!(episode.run().expect("asks"));
    let uavs: Vec<u32> = episode.pending().iter().map(|p| p.uav).collect();
    assert_eq!(uavs, [0, 1]);
}

#[test]
fn episodes_over_threads_run_as_they_run_alone() {
    let seeds = [11, 12, 13];
    let alone: Vec<String> = seeds
        .iter()
        .map(|&seed| {
            let mut e = Episode::new(&spec(seed, &[0])).expect("episode");
            play(&mut e, |_, _| Some(turn(0.5)));
            e.timeseries_csv()
        })
        .collect();
    let episodes = seeds
        .iter()
        .map(|&seed| Episode::new(&spec(seed, &[0])).expect("episode"))
        .collect();
    let mut vector = Episodes::new(episodes, 2);
    let all: Vec<usize> = (0..seeds.len()).collect();
    loop {
        let live: Vec<usize> = all
            .iter()
            .copied()
            .filter(|&i| !vector.episodes()[i].finished())
            .collect();
        if live.is_empty() {
            break;
        }
        for (i, asking) in live.iter().zip(vector.run(&live)) {
            if asking.expect("run") {
                let e = &mut vector.episodes_mut()[*i];
                let p = e.pending()[0].clone();
                e.answer(p.uav, &turn(0.5).encode(p.step, p.uav))
                    .expect("answer");
            }
        }
    }
    let together: Vec<String> = vector
        .episodes()
        .iter()
        .map(Episode::timeseries_csv)
        .collect();
    assert_eq!(together, alone);
}

#[test]
fn under_the_sets_exchange_the_observers_read_the_estimates() {
    let mut s = spec(8, &[0]);
    s.overrides.push("comms.exchange=sets".to_owned());
    let mut episode = Episode::new(&s).expect("episode");
    play(&mut episode, |_, _| Some(turn(0.0)));
    assert_eq!(episode.series().len(), 24);
    for m in episode.series() {
        assert_eq!((m.live_agents, m.estimates, m.violations), (3, 3, 0));
    }
    assert!(episode.fleet().states().iter().all(Vec::is_empty));
}
