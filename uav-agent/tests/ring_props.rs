//! The token ring ([`uav_agent::guidance::ring`]) under the world's reading of who is live
//! (`comms.liveness = "world"`: every agent given the same live set; the radio's reading is
//! checked in `ring_loss_props`) in a simulated fleet: N = 2..6 agents over
//! several rounds, driven by a seeded event queue with random deaths, message delays,
//! duplicated, reordered and late (older-round) tokens, and stalled agents whose waiters time
//! out. Each agent follows the agent loop's protocol (`Agent::decide`): drain the tokens, ask
//! for its turn, give every holder one bounded wait and declare it silent when it runs out,
//! plan (taking some time, during which tokens queue up), pass.
//!
//! Properties:
//! - every agent decides at most once per round;
//! - whenever an agent decides, every plan delivered to it before in the round is in its
//!   `others`;
//! - with consistent views (no holder declared silent in the round yet), no two agents
//!   decide at the same time;
//! - takeovers happen one at a time: two agents decide at the same time only if one of
//!   them had an out-of-date view (it was stopped this round, or a token reached it, or is
//!   still on its way to it, later than normal delays);
//! - at the end of each round every survivor has decided (liveness) and holds every plan
//!   made in the round, in the same order as every other survivor.

use std::collections::{BTreeMap, BTreeSet};

use proptest::prelude::*;
use protocol::camera::CameraPose;
use protocol::scenario::Liveness;
use protocol::wire::{GuidanceToken, PlannedView};
use sets::math::Point3;
use uav_agent::guidance::{TokenRing, Turn};

/// The bounded wait for one holder, in ticks.
const WAIT: u64 = 100;
/// Normal message delays are 1 to 10 ticks, the slow ones 60 to 250: a token that takes
/// longer than this is late, and its receiver's view may lag what its peers' waits assume.
const LATE: u64 = 40;
/// Steps per guidance period.
const STEPS: u64 = 6;

/// splitmix64: the seeded source of every random choice of a run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `lo..=hi`.
    fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next() % (hi - lo + 1)
    }

    fn percent(&mut self, p: u64) -> bool {
        self.next() % 100 < p
    }
}

/// The plan of `uav` in `round` (the round in the pose, so plans of rounds are told apart).
fn plan(uav: u32, round: u64) -> PlannedView {
    PlannedView {
        uav,
        poses: vec![CameraPose {
            position: Point3::new(uav as f64, 0.0, 80.0),
            yaw: round as f64,
        }],
    }
}

#[derive(Clone, Debug)]
enum Event {
    /// The round's guidance step reaches the agent.
    Enter,
    /// A token arrives (sent at that time).
    Deliver(GuidanceToken, u64),
    /// The agent's planning is over: it passes.
    Finish,
    /// The agent looks at its turn again (a wait slice ended).
    Poke,
    /// The agent is killed.
    Die,
    /// The agent learns that a peer is dead.
    LearnDeath(u32),
    /// The agent is stopped for this long.
    Stall(u64),
    /// The agent runs again.
    Resume,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    Idle,
    Waiting,
    Deciding,
    Done,
    Dead,
}

struct Agent {
    ring: TokenRing,
    phase: Phase,
    /// The UAVs this agent believes live, itself included.
    live: BTreeSet<u32>,
    stalled: bool,
    /// Planning finished while stopped: pass on resume.
    finish_pending: bool,
    /// Events held while stopped or planning.
    deferred: Vec<Event>,
    /// The holder waited for and when the wait runs out.
    waiting: Option<(u32, u64)>,
    /// UAVs whose plans of the current round were delivered to this agent.
    delivered: BTreeSet<u32>,
    /// This agent's view was out of date this round: it was stopped, or a token reached it
    /// more than [`LATE`] after it was sent (see also [`Sim::view_stale`]).
    stale_view: bool,
}

struct Sim {
    rng: Rng,
    now: u64,
    seq: u64,
    queue: BTreeMap<(u64, u64), (u32, Event)>,
    agents: Vec<Agent>,
    round: u64,
    /// Some holder was declared silent this round.
    timeouts: bool,
    /// Plans passed this round.
    made: BTreeMap<u32, PlannedView>,
    /// Decisions per agent this round.
    decisions: BTreeMap<u32, u32>,
    /// Every token sent, for late duplicates.
    history: Vec<GuidanceToken>,
    deaths: usize,
    stats: Stats,
    /// Print every event (`RING_TRACE=1`).
    trace: bool,
}

/// What a run went through, to check that the simulation reaches the cases it is for.
#[derive(Clone, Copy, Debug, Default)]
struct Stats {
    /// Holders declared silent.
    silent: u64,
    /// Decisions started while another agent was deciding (after timeouts).
    overlaps: u64,
    /// Tokens that carried a plan the receiver lacked while lacking one it had.
    merges: u64,
    /// Agents killed while deciding.
    killed_deciding: u64,
    /// Agents killed while they were the holder others waited for.
    killed_waited_for: u64,
    /// Tokens of an older round dropped.
    stale: u64,
    /// Tokens delivered twice or more.
    duplicates: u64,
}

impl Sim {
    fn new(n: u32, seed: u64) -> Self {
        let all: BTreeSet<u32> = (0..n).collect();
        Self {
            rng: Rng(seed),
            now: 0,
            seq: 0,
            queue: BTreeMap::new(),
            agents: (0..n)
                .map(|i| Agent {
                    ring: TokenRing::new(i, Liveness::World),
                    phase: Phase::Idle,
                    live: all.clone(),
                    stalled: false,
                    finish_pending: false,
                    deferred: Vec::new(),
                    waiting: None,
                    delivered: BTreeSet::new(),
                    stale_view: false,
                })
                .collect(),
            round: 0,
            timeouts: false,
            made: BTreeMap::new(),
            decisions: BTreeMap::new(),
            history: Vec::new(),
            deaths: 0,
            stats: Stats::default(),
            trace: std::env::var_os("RING_TRACE").is_some(),
        }
    }

    fn at(&mut self, time: u64, uav: u32, event: Event) {
        self.seq += 1;
        self.queue.insert((time, self.seq), (uav, event));
    }

    fn alive(&self) -> Vec<u32> {
        (0..self.agents.len() as u32)
            .filter(|&i| self.agents[i as usize].phase != Phase::Dead)
            .collect()
    }

    fn run_round(&mut self, round: u64) -> Result<(), TestCaseError> {
        self.round = round;
        self.timeouts = false;
        self.made.clear();
        self.decisions.clear();
        let t0 = self.now + 10;
        let n = self.agents.len() as u64;
        for i in self.alive() {
            let a = &mut self.agents[i as usize];
            a.phase = Phase::Idle;
            a.waiting = None;
            a.delivered.clear();
            a.stale_view = false;
            let at = t0 + self.rng.range(0, 20);
            self.at(at, i, Event::Enter);
        }
        let alive = self.alive();
        if self.deaths + 1 < self.agents.len() && self.rng.percent(30) {
            let victim = alive[self.rng.range(0, alive.len() as u64 - 1) as usize];
            let at = t0 + self.rng.range(0, 150);
            self.at(at, victim, Event::Die);
            self.deaths += 1;
        }
        for _ in 0..self.rng.range(0, 2) {
            if self.rng.percent(50) {
                let who = alive[self.rng.range(0, alive.len() as u64 - 1) as usize];
                let (at, long) = (t0 + self.rng.range(0, 200), self.rng.range(20, 400));
                self.at(at, who, Event::Stall(long));
            }
        }
        if !self.history.is_empty() {
            for _ in 0..self.rng.range(0, 2) {
                let old =
                    self.history[self.rng.range(0, self.history.len() as u64 - 1) as usize].clone();
                let (who, at) = (self.rng.range(0, n - 1) as u32, t0 + self.rng.range(0, 200));
                self.at(at, who, Event::Deliver(old, 0));
            }
        }
        while let Some(((time, _), (uav, event))) = self.queue.pop_first() {
            self.now = time;
            if self.trace {
                let what = match &event {
                    Event::Deliver(t, sent) => format!(
                        "Deliver(round {} from {} sent {} plans {:?} holder {})",
                        t.round,
                        t.issued_by,
                        sent,
                        t.plans.iter().map(|p| p.uav).collect::<Vec<_>>(),
                        t.holder
                    ),
                    e => format!("{e:?}"),
                };
                let a = &self.agents[uav as usize];
                eprintln!("{time:5} UAV {uav} {:?} {what}", a.phase);
            }
            self.handle(uav, event)?;
        }
        // The round is over: every event has been handled.
        let mut agreed: Option<Vec<PlannedView>> = None;
        for i in self.alive() {
            let a = &self.agents[i as usize];
            prop_assert_eq!(
                a.phase,
                Phase::Done,
                "UAV {} never decided in round {}",
                i,
                round
            );
            prop_assert_eq!(self.decisions.get(&i), Some(&1));
            let plans = a.ring.plans(round);
            let held: BTreeMap<u32, PlannedView> =
                plans.iter().map(|p| (p.uav, p.clone())).collect();
            prop_assert_eq!(plans.len(), held.len(), "two plans of one UAV: {:?}", plans);
            prop_assert_eq!(&held, &self.made, "UAV {} lost plans of round {}", i, round);
            if let Some(u) = &agreed {
                prop_assert_eq!(u, &plans, "survivors disagree on the order of the plans");
            }
            agreed = Some(plans);
        }
        Ok(())
    }

    fn handle(&mut self, uav: u32, event: Event) -> Result<(), TestCaseError> {
        let a = &mut self.agents[uav as usize];
        if a.phase == Phase::Dead {
            return Ok(());
        }
        if let Event::Deliver(token, sent) = &event {
            // Late, even if held until the agent runs or has planned.
            a.stale_view |= token.round == self.round && self.now > sent + LATE;
        }
        match event {
            Event::Die => {
                if a.phase == Phase::Deciding {
                    self.stats.killed_deciding += 1;
                }
                a.phase = Phase::Dead;
                a.deferred.clear();
                if self
                    .agents
                    .iter()
                    .any(|b| b.waiting.is_some_and(|(h, _)| h == uav))
                {
                    self.stats.killed_waited_for += 1;
                }
                for j in self.alive() {
                    let at = self.now + self.rng.range(0, 20);
                    self.at(at, j, Event::LearnDeath(uav));
                }
                return Ok(());
            }
            Event::Stall(long) => {
                if !a.stalled {
                    a.stale_view = true;
                    a.stalled = true;
                    let at = self.now + long;
                    self.at(at, uav, Event::Resume);
                }
                return Ok(());
            }
            Event::Resume => {
                a.stalled = false;
                if a.finish_pending {
                    a.finish_pending = false;
                    self.finish(uav);
                }
                let a = &mut self.agents[uav as usize];
                let deferred = std::mem::take(&mut a.deferred);
                for e in deferred {
                    self.at(self.now, uav, e);
                }
                self.at(self.now, uav, Event::Poke);
                return Ok(());
            }
            _ => {}
        }
        if a.stalled {
            match event {
                Event::Finish => a.finish_pending = true,
                Event::Poke => {}
                e => a.deferred.push(e),
            }
            return Ok(());
        }
        match event {
            Event::Finish => self.finish(uav),
            Event::Enter => {
                a.phase = Phase::Waiting;
                self.poll(uav)?;
            }
            Event::Poke => self.poll(uav)?,
            Event::Deliver(..) | Event::LearnDeath(_) if a.phase == Phase::Deciding => {
                a.deferred.push(event);
            }
            Event::Deliver(token, _) => {
                if token.round == self.round {
                    a.delivered.extend(token.plans.iter().map(|p| p.uav));
                    let had: BTreeSet<u32> =
                        a.ring.plans(token.round).iter().map(|p| p.uav).collect();
                    let brings: BTreeSet<u32> = token.plans.iter().map(|p| p.uav).collect();
                    if !had.is_subset(&brings) && !brings.is_subset(&had) {
                        self.stats.merges += 1;
                    }
                }
                let stale = a.ring.stale_tokens;
                a.ring.observe(token);
                self.stats.stale += a.ring.stale_tokens - stale;
                self.poll(uav)?;
            }
            Event::LearnDeath(dead) => {
                a.live.remove(&dead);
                self.poll(uav)?;
            }
            Event::Die | Event::Stall(_) | Event::Resume => unreachable!(),
        }
        Ok(())
    }

    /// Whether `uav` has had an out-of-date view this round: stopped, or a token of the
    /// round reached it, or has yet to reach it, more than [`LATE`] after it was sent.
    fn view_stale(&self, uav: u32) -> bool {
        self.agents[uav as usize].stale_view
            || self.queue.values().any(|(to, e)| {
                *to == uav
                    && matches!(e, Event::Deliver(t, sent)
                        if t.round == self.round && self.now > sent + LATE)
            })
    }

    /// The agent loop's `decide`, one pass: ask for the turn, time out the holder, decide.
    fn poll(&mut self, uav: u32) -> Result<(), TestCaseError> {
        let round = self.round;
        loop {
            let a = &mut self.agents[uav as usize];
            if a.phase != Phase::Waiting {
                return Ok(());
            }
            match a.ring.turn(round, &a.live) {
                Turn::Done => {
                    prop_assert!(false, "UAV {} told Done before deciding", uav);
                }
                Turn::Decide { others } => {
                    let seen: BTreeSet<u32> = others.iter().map(|p| p.uav).collect();
                    prop_assert!(
                        a.delivered.is_subset(&seen),
                        "UAV {} decides around {:?} but was delivered plans of {:?}",
                        uav,
                        seen,
                        a.delivered
                    );
                    prop_assert!(!seen.contains(&uav));
                    a.phase = Phase::Deciding;
                    if self.trace {
                        eprintln!("      UAV {uav} decides around {seen:?}");
                    }
                    a.waiting = None;
                    let count = self.decisions.entry(uav).or_default();
                    *count += 1;
                    prop_assert_eq!(*count, 1, "UAV {} decided twice in round {}", uav, round);
                    let busy: Vec<usize> = (0..self.agents.len())
                        .filter(|&j| j != uav as usize)
                        .filter(|&j| self.agents[j].phase == Phase::Deciding)
                        .collect();
                    if !busy.is_empty() {
                        self.stats.overlaps += 1;
                    }
                    // Takeovers one at a time: only an agent whose view was out of date
                    // decides alongside another.
                    let excused =
                        self.view_stale(uav) || busy.iter().all(|&j| self.view_stale(j as u32));
                    prop_assert!(
                        excused,
                        "UAV {} decides while {:?} do, both up to date",
                        uav,
                        busy
                    );
                    if !self.timeouts {
                        prop_assert!(
                            busy.is_empty(),
                            "UAV {} decides while {:?} do, with no timeout",
                            uav,
                            busy
                        );
                    }
                    let at = self.now + self.rng.range(1, 10);
                    self.at(at, uav, Event::Finish);
                    return Ok(());
                }
                Turn::Wait { holder } => {
                    prop_assert!(holder != uav);
                    let now = self.now;
                    let (deadline, fresh) = match a.waiting {
                        Some((h, d)) if h == holder => (d, false),
                        _ => {
                            a.waiting = Some((holder, now + WAIT));
                            (now + WAIT, true)
                        }
                    };
                    if now < deadline {
                        if fresh {
                            self.at(deadline, uav, Event::Poke);
                        }
                        return Ok(());
                    }
                    a.ring.holder_silent(round, holder);
                    if self.trace {
                        eprintln!("      UAV {uav} declares {holder} silent");
                    }
                    self.stats.silent += 1;
                    self.timeouts = true;
                }
            }
        }
    }

    /// Planning is over: pass the token to everyone (late, twice, or to itself at times).
    fn finish(&mut self, uav: u32) {
        let round = self.round;
        let a = &mut self.agents[uav as usize];
        let view = plan(uav, round);
        let token = a.ring.pass(round, round * STEPS, &a.live, view.clone());
        a.phase = Phase::Done;
        self.made.insert(uav, view);
        self.history.push(token.clone());
        let deferred = std::mem::take(&mut a.deferred);
        for e in deferred {
            self.at(self.now, uav, e);
        }
        for j in 0..self.agents.len() as u32 {
            let copies = if self.rng.percent(20) { 2 } else { 1 };
            if copies > 1 {
                self.stats.duplicates += 1;
            }
            for _ in 0..copies {
                if j == uav && self.rng.percent(50) {
                    continue;
                }
                let delay = if self.rng.percent(5) {
                    self.rng.range(60, 250)
                } else {
                    self.rng.range(1, 10)
                };
                self.at(self.now + delay, j, Event::Deliver(token.clone(), self.now));
            }
        }
    }
}

fn simulate(n: u32, rounds: u64, seed: u64) -> Result<Stats, TestCaseError> {
    let mut sim = Sim::new(n, seed);
    for round in 0..rounds {
        sim.run_round(round)?;
    }
    Ok(sim.stats)
}

/// Replays one run with its events printed: `RING_SEED=... RING_N=... RING_TRACE=1`.
#[test]
fn replay() {
    let var = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<u64>().ok());
    if let (Some(seed), Some(n)) = (var("RING_SEED"), var("RING_N")) {
        let rounds = var("RING_ROUNDS").unwrap_or(3);
        simulate(n as u32, rounds, seed).expect("the properties hold");
    }
}

/// The runs below do go through the cases the properties are about.
#[test]
fn the_simulation_reaches_every_case() {
    let mut total = Stats::default();
    for seed in 0..300 {
        let s = simulate(2 + (seed % 5) as u32, 5, seed).expect("the properties hold");
        total.silent += s.silent;
        total.overlaps += s.overlaps;
        total.merges += s.merges;
        total.killed_deciding += s.killed_deciding;
        total.killed_waited_for += s.killed_waited_for;
        total.stale += s.stale;
        total.duplicates += s.duplicates;
    }
    eprintln!("{total:?}");
    let Stats {
        silent,
        overlaps,
        merges,
        killed_deciding,
        killed_waited_for,
        stale,
        duplicates,
    } = total;
    for (what, count) in [
        ("silent holders", silent),
        ("concurrent deciders after timeouts", overlaps),
        ("merges of concurrent tokens", merges),
        ("agents killed while deciding", killed_deciding),
        ("holders killed while waited for", killed_waited_for),
        ("stale tokens", stale),
        ("duplicated tokens", duplicates),
    ] {
        assert!(count >= 5, "only {count} {what} in 300 runs");
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 512,
        // Integration tests have no lib.rs to store regressions next to; the seed is printed.
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn the_ring_keeps_one_holder_and_every_plan(n in 2u32..=6, rounds in 3u64..=6, seed in any::<u64>()) {
        simulate(n, rounds, seed)?;
    }
}
