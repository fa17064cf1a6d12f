//! The round-robin guidance token, as a state machine that does no I/O.
//!
//! One round per guidance period. Every agent sees every token sent (the guidance service is
//! all-to-all) and keeps, per round, the MERGE of all the round's tokens it has seen: the
//! union of their plans (at most one plan per UAV; the first seen is kept, and an agent's own
//! plan always wins for itself), the round's order, and the holders it gave up on. A token of
//! an older round is counted in [`TokenRing::stale_tokens`] and dropped; a token of a newer
//! round replaces the older round. Tokens may therefore arrive late, twice or out of order,
//! and two UAVs that took the turn concurrently lose none of each other's plans.
//!
//! Who an agent waits for depends on where it learns which UAVs are live (`comms.liveness`,
//! [`Liveness`]): under the world's reading every agent is given the same live set, and one
//! holder, computed alike by all, decides at a time; under the radio's reading (the default)
//! each agent knows live only the UAVs its radio heard, and waits for the UAVs before it.
//!
//! The rules of a round under the world's reading (`comms.liveness = "world"`):
//! - **Order.** The first holder issues the token with the UAVs it believes live, ascending;
//!   a UAV that decides while missing from the order appends itself. Merged orders: the
//!   longest order seen (ties: the lexicographically smallest), then every other UAV named by
//!   some token, ascending; then, for this agent's turn, the live UAVs named by no token,
//!   ascending (late joiners). The result depends only on the tokens seen and the live set.
//! - **Holder.** One UAV holds the turn, computed by every agent from the same inputs (the
//!   round's order, the plans gathered, the live set and the silent holders), never read from
//!   a token: starting after the furthest UAV of the order that has decided (the start of
//!   the order when none has), the first UAV, wrapping around, that is live, has not decided
//!   and is not silent. Agents with the same view agree on it, so one live holder decides at
//!   a time. A holder known dead is skipped at once.
//! - **Silent holders.** A holder that is alive but does not pass the token (stalled, e.g.
//!   SIGSTOPped) is skipped once the caller's bounded wait for THAT holder runs out
//!   ([`TokenRing::holder_silent`]); it is treated as dead for the rest of the round. The
//!   next live undecided UAV after it takes over, and every other waiter waits for that new
//!   holder with a fresh bounded wait, so takeovers too happen one at a time. (Waits that
//!   started at different times may still run out at different times: then two UAVs can
//!   decide concurrently, and the merge keeps both plans.)
//! - **Lost tokens.** On lossy links (`comms.loss`), or out of the radio's range
//!   (`comms.range_m` with `comms.token_range = "radio"`), the receiver decides whether the
//!   radio carried a token ([`TokenRing::receive`]). A lost token still says one thing for
//!   sure: its sender decided (only a UAV that decided sends one). Its sender is then skipped
//!   at once for the rest of the round, as a silent holder is, and its plan stays unknown here
//!   (a later token that carries it still brings it). Since every agent skips a UAV only once
//!   it has decided, the holder each agent computes is the same one as on perfect links, one
//!   UAV at a time; a holder that lost every earlier token decides around no plans. So a round
//!   ends with every live agent deciding once, without waiting for anything, and what each
//!   decides around is the plans of the tokens delivered to it: the same in every run with
//!   the same seed, as long as a token reaches every agent before any token sent because of
//!   it (on one host a token is in every queue once sent; across hosts the bridges' in-order
//!   links through one router keep that order).
//! - **Once per round.** An agent decides at most once per round, and not in a round older
//!   than one it decided in. An agent that comes back or joins late (the round complete
//!   without it) is still the holder once the others have decided, and decides once, around
//!   all the plans. An agent asked about a round older than the newest it has seen tokens of
//!   decides at once around no plans (that round's plans were dropped with it).
//! - **Passing.** [`TokenRing::pass`] adds this agent's plan to the merge and returns the
//!   token to publish: every merged plan, the merged order, and as holder the next holder by
//!   the rule above ([`ROUND_COMPLETE`] when nobody is left), for information only.
//!
//! (The first holder is the lowest live UAV; a lost or stalled turn is taken over by the next
//! live UAV in the order, which keeps the round's order and loses no plan.)
//!
//! Under the radio's reading (`comms.liveness = "radio"`) agents do not share a live set:
//! each knows live the peers whose estimate it fused at the step (`crate::agent`), so a UAV
//! out of range, or whose estimate the radio lost, is not live to it, and two agents may see
//! different UAVs decide last. The holder above would then let two agents wait for each other
//! (each starting after a different "furthest" UAV), and what an agent decides around would
//! depend on which tokens happened to come first. So the radio's reading needs no agreement:
//! - **Order.** Ascending UAV ids, which every agent knows without a message.
//! - **Predecessors.** An agent waits for the token of each UAV before it that it knows live,
//!   lowest first, until it has read it, lost it (to loss or range) or given up on it (the
//!   caller's bounded wait for a silent holder; the agent loop gives up at once on a UAV
//!   whose process is gone or that the world no longer serves, whose token cannot come).
//!   Waits point only to lower ids, so they cannot form a cycle: the lowest UAV that has not
//!   decided never waits, and every live agent decides once in the round, none of them
//!   waiting out a timeout. Nobody waits for a UAV it did not hear: a UAV out of everyone's
//!   range decides at once around no plans, and a fleet that the range splits into groups
//!   runs one chain of turns per group, each from its lowest UAV (two tokens at once, for one
//!   round: each round starts afresh from what the agents heard at its step).
//! - **Plans.** An agent decides around the plans carried by the tokens it read from its
//!   predecessors, and passes exactly those and its own (in ascending order of UAV). Both are
//!   fixed once its waits are over: a token of a UAV it does not wait for may have come by
//!   then or not, and is not used. So what each agent decides around is the same in every
//!   run with the same seed, whatever the order messages come in. The plan of a UAV out of an
//!   agent's range reaches it only inside a token it read from a UAV in range, as a radio
//!   relay would carry it.
//! - **Fleet.** The round's fleet ([`TokenRing::fleet`]) is the UAVs the agent knows live and
//!   itself; the token's order is that fleet and its holder the next of them after the agent.
//! - **Once per round**, older and newer rounds, as under the world's reading.
//!
//! When every agent hears every other (unlimited range, no loss, nobody dead, stalled or
//! late) the two readings make the same decisions around the same plans, and send the same
//! tokens.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Bound;

use protocol::scenario::Liveness;
use protocol::wire::{GuidanceToken, PlannedView};

/// Holder value of a token whose round is complete.
pub const ROUND_COMPLETE: u32 = u32::MAX;

/// What the agent should do about the current round.
#[derive(Clone, Debug, PartialEq)]
pub enum Turn {
    /// Another UAV holds the turn: wait for it (bounded; see [`TokenRing::holder_silent`]).
    Wait {
        /// The UAV expected to act.
        holder: u32,
    },
    /// Decide now, planning around these plans.
    Decide {
        /// Plans of the UAVs that decided before, in the round's order.
        others: Vec<PlannedView>,
    },
    /// This agent already decided this round.
    Done,
}

/// One round as an agent knows it: the merge of the round's tokens it saw.
#[derive(Clone, Debug)]
struct RoundState {
    round: u64,
    /// Smallest step carried by the round's tokens.
    step: Option<u64>,
    /// The longest order seen (ties: the lexicographically smallest).
    best_order: Vec<u32>,
    /// Every UAV named by the order of some token.
    named: BTreeSet<u32>,
    /// One plan per UAV that decided.
    plans: BTreeMap<u32, PlannedView>,
    /// Holders named by a token, with the smallest issuer of a token naming them.
    issuers: BTreeMap<u32, u32>,
    /// Holders this agent gave up waiting for, and senders of tokens the radio lost.
    silent: BTreeSet<u32>,
    /// Per UAV whose token of the round this agent read (the first one), the UAVs whose plans
    /// it carried: what a decision uses under the radio's reading.
    carried: BTreeMap<u32, Vec<u32>>,
}

impl RoundState {
    fn new(round: u64) -> Self {
        Self {
            round,
            step: None,
            best_order: Vec::new(),
            named: BTreeSet::new(),
            plans: BTreeMap::new(),
            issuers: BTreeMap::new(),
            silent: BTreeSet::new(),
            carried: BTreeMap::new(),
        }
    }

    /// Merges `token`, read from `sender` when known.
    fn merge(&mut self, token: GuidanceToken, sender: Option<u32>) {
        if let Some(sender) = sender {
            self.carried
                .entry(sender)
                .or_insert_with(|| token.plans.iter().map(|p| p.uav).collect());
        }
        self.step = Some(self.step.map_or(token.step, |s| s.min(token.step)));
        self.named.extend(token.order.iter().copied());
        let longer = token.order.len() > self.best_order.len()
            || (token.order.len() == self.best_order.len() && token.order < self.best_order);
        if longer {
            self.best_order = token.order;
        }
        if token.holder != ROUND_COMPLETE {
            let issuer = self.issuers.entry(token.holder).or_insert(token.issued_by);
            *issuer = (*issuer).min(token.issued_by);
        }
        for plan in token.plans {
            self.plans.entry(plan.uav).or_insert(plan);
        }
    }

    /// The merged order of the round's tokens.
    fn order(&self) -> Vec<u32> {
        let mut order = self.best_order.clone();
        let rest: Vec<u32> = self
            .named
            .iter()
            .copied()
            .filter(|u| !self.best_order.contains(u))
            .collect();
        order.extend(rest);
        order
    }

    /// The order `me` publishes with its plan: the merged order with `me` appended if
    /// missing, or, when no token named an order yet (`me` is the round's first holder), the
    /// live UAVs and `me`, ascending.
    fn order_to_publish(&self, me: u32, live: &BTreeSet<u32>) -> Vec<u32> {
        let mut order = self.order();
        if order.is_empty() {
            let first: BTreeSet<u32> = live.iter().copied().chain([me]).collect();
            return first.into_iter().collect();
        }
        if !order.contains(&me) {
            order.push(me);
        }
        order
    }

    /// Under the radio's reading, the UAV `me` waits for: the lowest UAV before it that it
    /// knows live and whose token it has not read, lost or given up on. `None`: `me` decides.
    fn first_awaited_predecessor(&self, me: u32, live: &BTreeSet<u32>) -> Option<u32> {
        live.range(..me)
            .copied()
            .find(|u| !self.carried.contains_key(u) && !self.silent.contains(u))
    }

    /// Under the radio's reading, the plans `me` decides around: those carried by the tokens
    /// it read from the UAVs before it that it knows live, in ascending order of UAV.
    fn predecessors_plans(&self, me: u32, live: &BTreeSet<u32>) -> Vec<PlannedView> {
        let uavs: BTreeSet<u32> = live
            .range(..me)
            .filter_map(|u| self.carried.get(u))
            .flatten()
            .copied()
            .filter(|&u| u != me)
            .collect();
        uavs.iter()
            .filter_map(|u| self.plans.get(u))
            .cloned()
            .collect()
    }

    /// Whom `me` waits for under `liveness` (`None` or `me`: it decides).
    fn awaited(&self, me: u32, live: &BTreeSet<u32>, liveness: Liveness) -> Option<u32> {
        match liveness {
            Liveness::World => self.holder(me, live),
            Liveness::Radio => self.first_awaited_predecessor(me, live),
        }
    }

    /// The plans `me` decides around under `liveness`.
    fn decided_around(
        &self,
        me: u32,
        live: &BTreeSet<u32>,
        liveness: Liveness,
    ) -> Vec<PlannedView> {
        match liveness {
            Liveness::World => self.plans(),
            Liveness::Radio => self.predecessors_plans(me, live),
        }
    }

    /// The plans, in the round's order (UAVs outside it last, ascending).
    fn plans(&self) -> Vec<PlannedView> {
        let order = self.order();
        let mut plans: Vec<&PlannedView> = self.plans.values().collect();
        plans.sort_by_key(|p| {
            let at = order.iter().position(|&u| u == p.uav);
            (at.unwrap_or(usize::MAX), p.uav)
        });
        plans.into_iter().cloned().collect()
    }

    /// The holder seen by `me` with this live set: after the furthest UAV of the order that
    /// has decided, the first one, wrapping around, that is live (`me` always is), has not
    /// decided and is not silent. `None` when the round is complete.
    fn holder(&self, me: u32, live: &BTreeSet<u32>) -> Option<u32> {
        let mut order = self.order();
        let late: BTreeSet<u32> = live
            .iter()
            .copied()
            .chain([me])
            .filter(|u| !order.contains(u))
            .collect();
        order.extend(late);
        let start = order
            .iter()
            .rposition(|u| self.plans.contains_key(u))
            .map_or(0, |p| p + 1);
        let n = order.len();
        (0..n).map(|i| order[(start + i) % n]).find(|&u| {
            (u == me || live.contains(&u))
                && !self.plans.contains_key(&u)
                && !self.silent.contains(&u)
        })
    }
}

/// One agent's view of the token ring.
#[derive(Clone, Debug)]
pub struct TokenRing {
    me: u32,
    /// Where the live sets the agent gives come from (`comms.liveness`).
    liveness: Liveness,
    /// The newest round this agent decided in.
    decided_round: Option<u64>,
    /// The newest round seen (a token, a turn taken or a silent holder).
    current: Option<RoundState>,
    /// Tokens dropped because they belonged to an older round.
    pub stale_tokens: u64,
}

impl TokenRing {
    /// The ring as seen by UAV `me`, whose live sets are read as `liveness` says.
    pub fn new(me: u32, liveness: Liveness) -> Self {
        Self {
            me,
            liveness,
            decided_round: None,
            current: None,
            stale_tokens: 0,
        }
    }

    /// The state of `round`, started afresh if it is newer than the current one; `None` if
    /// it is older.
    fn state_mut(&mut self, round: u64) -> Option<&mut RoundState> {
        if self.current.as_ref().is_none_or(|s| s.round < round) {
            self.current = Some(RoundState::new(round));
        }
        self.current.as_mut().filter(|s| s.round == round)
    }

    /// Whether `round` is older than the newest round seen.
    fn is_past(&self, round: u64) -> bool {
        self.current.as_ref().is_some_and(|s| s.round > round)
    }

    /// Takes note of a token seen on the guidance service (including this agent's own): it is
    /// merged into its round's state, replaces an older round, or is counted stale and dropped
    /// if its round is older than the newest seen.
    ///
    /// The token's sender is not known here: under the radio's reading such a token brings its
    /// plans but does not end a wait ([`TokenRing::receive`] does).
    pub fn observe(&mut self, token: GuidanceToken) {
        self.merge(token, None);
    }

    fn merge(&mut self, token: GuidanceToken, sender: Option<u32>) {
        match self.state_mut(token.round) {
            Some(state) => state.merge(token, sender),
            None => self.stale_tokens += 1,
        }
    }

    /// Takes note of a token `sender` sent over a link that may lose it: merged when the radio
    /// `delivered` it ([`TokenRing::observe`]), and read from `sender`; otherwise `sender`
    /// decided with a plan this agent will not see, and is skipped at once for the rest of the
    /// round, as a holder whose wait ran out is ([`TokenRing::holder_silent`]), so nobody
    /// waits for it.
    pub fn receive(&mut self, token: GuidanceToken, sender: u32, delivered: bool) {
        if delivered {
            self.merge(token, Some(sender));
        } else {
            self.holder_silent(token.round, sender);
        }
    }

    /// Records that this agent's bounded wait for `holder` ran out in `round`: `holder` is
    /// skipped as if dead for the rest of the round. (This agent never skips itself.)
    pub fn holder_silent(&mut self, round: u64, holder: u32) {
        let me = self.me;
        if let Some(state) = self.state_mut(round)
            && holder != me
        {
            state.silent.insert(holder);
        }
    }

    /// The plans of `round` gathered so far, merged, in the round's order (empty if `round` is
    /// not the newest round seen).
    pub fn plans(&self, round: u64) -> Vec<PlannedView> {
        self.current
            .as_ref()
            .filter(|s| s.round == round)
            .map(RoundState::plans)
            .unwrap_or_default()
    }

    /// What to do in `round`, given the UAVs this agent believes live (itself included).
    pub fn turn(&self, round: u64, live: &BTreeSet<u32>) -> Turn {
        if self.decided_round.is_some_and(|d| d >= round) {
            return Turn::Done;
        }
        if self.is_past(round) {
            return Turn::Decide { others: Vec::new() };
        }
        let fresh;
        let state = match self.current.as_ref().filter(|s| s.round == round) {
            Some(s) => s,
            None => {
                fresh = RoundState::new(round);
                &fresh
            }
        };
        if state.plans.contains_key(&self.me) {
            // A token already carries this UAV's plan (an earlier incarnation decided).
            return Turn::Done;
        }
        match state.awaited(self.me, live, self.liveness) {
            Some(h) if h != self.me => Turn::Wait { holder: h },
            _ => Turn::Decide {
                others: state.decided_around(self.me, live, self.liveness),
            },
        }
    }

    /// The fleet of `round` as this agent decides in it, given the UAVs it believes live: the
    /// order its token will carry ([`TokenRing::pass`]), ascending (the `setfleet` sweep
    /// shares the lanes among this fleet). Under the world's reading, a function of the
    /// round's tokens (of the live UAVs for the round's first holder, whose token sets the
    /// order), so the UAVs of a round agree on it, and a UAV that died is left out from the
    /// first round whose first holder knew it. Under the radio's reading, the UAVs this agent
    /// heard and itself: UAVs that hear each other alike agree on it.
    pub fn fleet(&self, round: u64, live: &BTreeSet<u32>) -> Vec<u32> {
        let mut fleet = match self.current.as_ref().filter(|s| s.round == round) {
            Some(state) => self.order_to_publish(state, live),
            None => self.order_to_publish(&RoundState::new(round), live),
        };
        fleet.sort_unstable();
        fleet
    }

    /// The order this agent's token carries in the round of `state`.
    fn order_to_publish(&self, state: &RoundState, live: &BTreeSet<u32>) -> Vec<u32> {
        match self.liveness {
            Liveness::World => state.order_to_publish(self.me, live),
            Liveness::Radio => live
                .iter()
                .copied()
                .chain([self.me])
                .collect::<BTreeSet<u32>>()
                .into_iter()
                .collect(),
        }
    }

    /// Records this agent's decision for `round` (started at `step`) and returns the token to
    /// publish: the plans it decided around plus `view` (under the world's reading every plan
    /// of the round merged so far), the round's order (this agent appended if missing; under
    /// the radio's reading its fleet) and as holder the next one by the ring's rule
    /// ([`ROUND_COMPLETE`] if nobody is left). The caller adds its pose
    /// ([`GuidanceToken::pose`]).
    pub fn pass(
        &mut self,
        round: u64,
        step: u64,
        live: &BTreeSet<u32>,
        view: PlannedView,
    ) -> GuidanceToken {
        let me = self.me;
        let liveness = self.liveness;
        self.decided_round = Some(self.decided_round.map_or(round, |d| d.max(round)));
        // A round older than the newest seen is decided alone, without touching the newest.
        let mut past = RoundState::new(round);
        let order = match self.current.as_ref().filter(|s| s.round == round) {
            Some(state) => self.order_to_publish(state, live),
            None => self.order_to_publish(&past, live),
        };
        let state = match self.state_mut(round) {
            Some(s) => s,
            None => &mut past,
        };
        let issued_by = state.issuers.get(&me).copied().unwrap_or(me);
        let step = state.step.unwrap_or(step);
        // Under the radio's reading, what this agent decided around, before its own plan joins.
        let decided_around =
            (liveness == Liveness::Radio).then(|| state.predecessors_plans(me, live));
        state.plans.insert(me, view);
        state.named.extend(order.iter().copied());
        if order.len() > state.best_order.len() {
            state.best_order.clone_from(&order);
        }
        let (plans, holder) = match decided_around {
            None => (state.plans(), state.holder(me, live)),
            Some(mut plans) => {
                plans.extend(state.plans.get(&me).cloned());
                plans.sort_by_key(|p| p.uav);
                let next = live.range((Bound::Excluded(me), Bound::Unbounded)).next();
                (plans, next.copied())
            }
        };
        GuidanceToken {
            round,
            step,
            order,
            holder: holder.unwrap_or(ROUND_COMPLETE),
            issued_by,
            plans,
            pose: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use protocol::camera::CameraPose;
    use protocol::radio::{Endpoint, Radio};
    use sets::math::Point3;

    use super::*;

    fn live(ids: &[u32]) -> BTreeSet<u32> {
        ids.iter().copied().collect()
    }

    fn view(uav: u32) -> PlannedView {
        PlannedView {
            uav,
            poses: Vec::new(),
        }
    }

    fn views(uavs: &[u32]) -> Vec<PlannedView> {
        uavs.iter().copied().map(view).collect()
    }

    fn others(turn: Turn) -> Vec<u32> {
        match turn {
            Turn::Decide { others } => others.iter().map(|p| p.uav).collect(),
            other => panic!("expected to decide, got {other:?}"),
        }
    }

    #[test]
    fn a_round_visits_every_live_uav_in_order() {
        let all = live(&[0, 1, 2]);
        let mut rings: Vec<TokenRing> =
            (0..3).map(|i| TokenRing::new(i, Liveness::World)).collect();
        assert_eq!(rings[1].turn(5, &all), Turn::Wait { holder: 0 });
        assert_eq!(rings[0].turn(5, &all), Turn::Decide { others: vec![] });
        let t = rings[0].pass(5, 30, &all, view(0));
        assert_eq!(t.holder, 1);
        assert_eq!(t.order, vec![0, 1, 2]);
        for r in &mut rings {
            r.observe(t.clone());
        }
        assert_eq!(rings[0].turn(5, &all), Turn::Done);
        assert_eq!(rings[2].turn(5, &all), Turn::Wait { holder: 1 });
        assert_eq!(
            rings[1].turn(5, &all),
            Turn::Decide {
                others: vec![view(0)]
            }
        );
        let t = rings[1].pass(5, 30, &all, view(1));
        rings[2].observe(t);
        assert_eq!(others(rings[2].turn(5, &all)), vec![0, 1]);
        let t = rings[2].pass(5, 30, &all, view(2));
        assert_eq!(t.holder, ROUND_COMPLETE);
        assert_eq!(t.plans, views(&[0, 1, 2]));
        assert_eq!(rings[2].turn(5, &all), Turn::Done);
    }

    #[test]
    fn a_dead_holder_is_skipped_at_once() {
        let mut r2 = TokenRing::new(2, Liveness::World);
        let mut r0 = TokenRing::new(0, Liveness::World);
        let t = r0.pass(1, 6, &live(&[0, 1, 2]), view(0));
        assert_eq!(t.holder, 1);
        r2.observe(t);
        // UAV 1 died while holding the token.
        assert_eq!(
            r2.turn(1, &live(&[0, 2])),
            Turn::Decide {
                others: vec![view(0)]
            }
        );
        let t = r2.pass(1, 6, &live(&[0, 2]), view(2));
        assert_eq!(t.issued_by, 2);
        assert_eq!(t.holder, ROUND_COMPLETE);
    }

    #[test]
    fn a_dead_issuer_is_replaced_by_the_lowest_live() {
        let r1 = TokenRing::new(1, Liveness::World);
        assert_eq!(r1.turn(0, &live(&[1, 2])), Turn::Decide { others: vec![] });
        let r2 = TokenRing::new(2, Liveness::World);
        assert_eq!(r2.turn(0, &live(&[1, 2])), Turn::Wait { holder: 1 });
    }

    /// Bug 3: every waiter used to decide once its wait ran out.
    #[test]
    fn a_silent_holder_has_exactly_one_successor() {
        let all = live(&[0, 1, 2, 3]);
        // No token yet and the first holder is stalled.
        let mut rings: Vec<TokenRing> =
            (0..4).map(|i| TokenRing::new(i, Liveness::World)).collect();
        for r in &mut rings[1..] {
            assert_eq!(r.turn(3, &all), Turn::Wait { holder: 0 });
            r.holder_silent(3, 0);
        }
        assert_eq!(rings[1].turn(3, &all), Turn::Decide { others: vec![] });
        assert_eq!(rings[2].turn(3, &all), Turn::Wait { holder: 1 });
        assert_eq!(rings[3].turn(3, &all), Turn::Wait { holder: 1 });
        // Mid-round: 0 passed to 1, which stalls; 2 and 3 both give up on it.
        let mut rings: Vec<TokenRing> =
            (0..4).map(|i| TokenRing::new(i, Liveness::World)).collect();
        let t = rings[0].pass(4, 24, &all, view(0));
        for r in &mut rings[2..] {
            r.observe(t.clone());
            assert_eq!(r.turn(4, &all), Turn::Wait { holder: 1 });
            r.holder_silent(4, 1);
        }
        assert_eq!(others(rings[2].turn(4, &all)), vec![0]);
        assert_eq!(rings[3].turn(4, &all), Turn::Wait { holder: 2 });
        let t = rings[2].pass(4, 24, &all, view(2));
        assert_eq!(t.issued_by, 2, "2 took over");
        assert_eq!(t.holder, 3);
        rings[3].observe(t);
        assert_eq!(others(rings[3].turn(4, &all)), vec![0, 2]);
    }

    /// Bug 1: a same-round token with as many plans used to replace the one kept.
    #[test]
    fn concurrent_takeovers_merge() {
        let all = live(&[0, 1, 2, 3]);
        let mut r0 = TokenRing::new(0, Liveness::World);
        let t0 = r0.pass(2, 12, &all, view(0));
        let (mut r1, mut r2) = (
            TokenRing::new(1, Liveness::World),
            TokenRing::new(2, Liveness::World),
        );
        r1.observe(t0.clone());
        r2.observe(t0.clone());
        // 2 gives up on a stalled 1 and takes over; 1 comes back and decides meanwhile.
        r2.holder_silent(2, 1);
        assert_eq!(others(r2.turn(2, &all)), vec![0]);
        let t2 = r2.pass(2, 12, &all, view(2));
        assert_eq!(others(r1.turn(2, &all)), vec![0]);
        let t1 = r1.pass(2, 12, &all, view(1));
        for tokens in [[&t2, &t1], [&t1, &t2]] {
            let mut r3 = TokenRing::new(3, Liveness::World);
            r3.observe(t0.clone());
            for t in tokens {
                r3.observe(t.clone());
                r3.observe(t.clone());
            }
            assert_eq!(r3.plans(2), views(&[0, 1, 2]));
            assert_eq!(others(r3.turn(2, &all)), vec![0, 1, 2]);
            let t3 = r3.pass(2, 12, &all, view(3));
            assert_eq!(t3.plans, views(&[0, 1, 2, 3]));
            assert_eq!(t3.holder, ROUND_COMPLETE);
            assert_eq!(r3.stale_tokens, 0);
        }
        // The merge does not depend on the order the tokens came in.
        r0.observe(t1);
        r0.observe(t2);
        assert_eq!(r0.plans(2), views(&[0, 1, 2]));
    }

    /// Bug 2: the search for the next holder after a dead one did not wrap around and fell
    /// back to the agent itself.
    #[test]
    fn the_next_holder_wraps_around_the_order() {
        let all = live(&[0, 1, 2, 3, 4]);
        let mut r0 = TokenRing::new(0, Liveness::World);
        let t0 = r0.pass(7, 42, &all, view(0));
        // 3 gave up on 1 and 2 (stalled) and passed to 4, which then died.
        let mut r3 = TokenRing::new(3, Liveness::World);
        r3.observe(t0.clone());
        r3.holder_silent(7, 1);
        r3.holder_silent(7, 2);
        assert_eq!(others(r3.turn(7, &all)), vec![0]);
        let t3 = r3.pass(7, 42, &all, view(3));
        assert_eq!(t3.holder, 4);
        // 1 and 2 come back: 1 is next after 4, wrapping around; 2 waits for it.
        let survivors = live(&[0, 1, 2, 3]);
        let (mut r1, mut r2) = (
            TokenRing::new(1, Liveness::World),
            TokenRing::new(2, Liveness::World),
        );
        for r in [&mut r1, &mut r2] {
            r.observe(t0.clone());
            r.observe(t3.clone());
        }
        assert_eq!(others(r1.turn(7, &survivors)), vec![0, 3]);
        assert_eq!(r2.turn(7, &survivors), Turn::Wait { holder: 1 });
        let t1 = r1.pass(7, 42, &survivors, view(1));
        assert_eq!(t1.holder, 2);
        r2.observe(t1);
        assert_eq!(others(r2.turn(7, &survivors)), vec![0, 1, 3]);
    }

    #[test]
    fn a_late_joiner_decides_once_around_all_plans() {
        let mut r0 = TokenRing::new(0, Liveness::World);
        let t0 = r0.pass(1, 6, &live(&[0, 1]), view(0));
        let mut r1 = TokenRing::new(1, Liveness::World);
        r1.observe(t0.clone());
        let t1 = r1.pass(1, 6, &live(&[0, 1]), view(1));
        assert_eq!(t1.holder, ROUND_COMPLETE);
        let mut r2 = TokenRing::new(2, Liveness::World);
        r2.observe(t1);
        r2.observe(t0);
        let all = live(&[0, 1, 2]);
        assert_eq!(others(r2.turn(1, &all)), vec![0, 1]);
        let t2 = r2.pass(1, 6, &all, view(2));
        assert_eq!(t2.order, vec![0, 1, 2]);
        assert_eq!(t2.holder, ROUND_COMPLETE);
        assert_eq!(r2.turn(1, &all), Turn::Done);
        // A late joiner waits for the holder of a round still under way.
        let mut r3 = TokenRing::new(3, Liveness::World);
        let t0 = r0.pass(2, 12, &live(&[0, 1]), view(0));
        r3.observe(t0);
        assert_eq!(r3.turn(2, &live(&[0, 1, 3])), Turn::Wait { holder: 1 });
    }

    #[test]
    fn old_tokens_are_stale_and_a_newer_round_replaces_the_older() {
        let mut r = TokenRing::new(3, Liveness::World);
        let mut a = TokenRing::new(0, Liveness::World);
        let t1 = a.pass(1, 6, &live(&[0, 3]), view(0));
        let t2 = a.pass(2, 12, &live(&[0, 3]), view(0));
        r.observe(t1.clone());
        assert_eq!(r.plans(1), views(&[0]));
        r.observe(t2);
        r.observe(t1);
        assert_eq!(r.stale_tokens, 1);
        assert_eq!(r.plans(1), vec![]);
        assert_eq!(
            r.turn(2, &live(&[0, 3])),
            Turn::Decide {
                others: vec![view(0)]
            }
        );
        // An agent still in round 1 decides at once; its token does not undo round 2.
        assert_eq!(r.turn(1, &live(&[0, 3])), Turn::Decide { others: vec![] });
        let late = r.pass(1, 6, &live(&[0, 3]), view(3));
        assert_eq!(late.round, 1);
        assert_eq!(r.plans(2), views(&[0]));
        assert_eq!(r.turn(1, &live(&[0, 3])), Turn::Done);
    }

    #[test]
    fn an_agent_decides_at_most_once_per_round() {
        let all = live(&[0, 1]);
        let mut r0 = TokenRing::new(0, Liveness::World);
        let t = r0.pass(3, 18, &all, view(0));
        assert_eq!(r0.turn(3, &all), Turn::Done);
        assert_eq!(
            r0.turn(2, &all),
            Turn::Done,
            "no going back to an older round"
        );
        // A restarted agent whose plan a token already carries does not decide again.
        let mut again = TokenRing::new(0, Liveness::World);
        again.observe(t);
        assert_eq!(again.turn(3, &all), Turn::Done);
    }

    /// The sweep's lanes are shared among the round's fleet: the order of the round's first
    /// token, which a UAV that died before the round starts is not in.
    #[test]
    fn the_fleet_is_the_rounds_order_and_leaves_a_dead_uav_out_of_the_next_round() {
        let all = live(&[0, 1, 2, 3]);
        let without_2 = live(&[0, 1, 3]);
        let mut first = TokenRing::new(0, Liveness::World);
        assert_eq!(first.fleet(1, &all), vec![0, 1, 2, 3]);
        let token = first.pass(1, 10, &all, view(0));
        // UAV 3 learns of 2's death during round 1: the round's fleet is still the token's.
        let mut later = TokenRing::new(3, Liveness::World);
        later.observe(token);
        assert_eq!(later.fleet(1, &without_2), vec![0, 1, 2, 3]);
        // Round 2's first holder knows: the fleet, and the order it passes on, leave 2 out.
        assert_eq!(first.fleet(2, &without_2), vec![0, 1, 3]);
        let token = first.pass(2, 12, &without_2, view(0));
        assert_eq!(token.order, vec![0, 1, 3]);
        later.observe(token.clone());
        assert_eq!(later.fleet(2, &without_2), vec![0, 1, 3]);
        // UAV 2 back in round 2, missing from the order: it plans as one of the fleet.
        let mut back = TokenRing::new(2, Liveness::World);
        back.observe(token);
        assert_eq!(back.fleet(2, &without_2), vec![0, 1, 2, 3]);
    }

    /// Agents at fixed positions in one round under the radio's reading: each knows live the
    /// UAVs in range of it (their estimates of the step were fused) and reads the tokens the
    /// radio carries to it, as the agent loop does.
    struct RadioFleet {
        radio: Radio,
        at: Vec<Endpoint>,
        rings: Vec<TokenRing>,
        live: Vec<BTreeSet<u32>>,
    }

    const ROUND: u64 = 4;
    const STEP: u64 = 24;

    impl RadioFleet {
        fn new(positions: &[(f64, f64)], range_m: f64) -> Self {
            let radio = Radio::perfect().with_range(range_m);
            let at: Vec<Endpoint> = (0u32..)
                .zip(positions)
                .map(|(uav, &(x, y))| Endpoint {
                    uav,
                    step: STEP,
                    pose: Some(CameraPose {
                        position: Point3::new(x, y, 60.0 + f64::from(uav)),
                        yaw: 0.0,
                    }),
                })
                .collect();
            let live = at
                .iter()
                .map(|me| {
                    let heard = at.iter().filter(|e| radio.fuses(me, e)).map(|e| e.uav);
                    heard.chain([me.uav]).collect()
                })
                .collect();
            let rings = (0..at.len() as u32)
                .map(|i| TokenRing::new(i, Liveness::Radio))
                .collect();
            Self {
                radio,
                at,
                rings,
                live,
            }
        }

        fn turn(&self, uav: u32) -> Turn {
            self.rings[uav as usize].turn(ROUND, &self.live[uav as usize])
        }

        fn fleet(&self, uav: u32) -> Vec<u32> {
            self.rings[uav as usize].fleet(ROUND, &self.live[uav as usize])
        }

        /// `uav` decides and sends its token to every agent; returns the token and who read it.
        fn pass(&mut self, uav: u32) -> (GuidanceToken, Vec<u32>) {
            let i = uav as usize;
            let mut token = self.rings[i].pass(ROUND, STEP, &self.live[i], view(uav));
            token.pose = self.at[i].pose;
            let mut readers = Vec::new();
            for (ring, receiver) in self.rings.iter_mut().zip(&self.at) {
                let read = self.radio.carries_token(receiver, &self.at[i]);
                ring.receive(token.clone(), uav, read);
                if read {
                    readers.push(receiver.uav);
                }
            }
            (token, readers)
        }
    }

    fn uavs(plans: &[PlannedView]) -> Vec<u32> {
        plans.iter().map(|p| p.uav).collect()
    }

    /// By hand, 100 m of range: 0 at (0, 0), 1 at (60, 80) (100 m from 0), 2 at (0, 101)
    /// (101 m from 0, 63.6 m from 1), 3 at (-70, 0) (70 m from 0, 152.6 m from 1, 122.9 m
    /// from 2). 0 hears 1 and 3; 1 hears 0 and 2; 2 hears 1; 3 hears 0.
    #[test]
    fn under_the_radio_an_agent_waits_for_the_uavs_before_it_that_it_heard() {
        let mut f = RadioFleet::new(
            &[(0.0, 0.0), (60.0, 80.0), (0.0, 101.0), (-70.0, 0.0)],
            100.0,
        );
        assert_eq!(
            f.live,
            [
                live(&[0, 1, 3]),
                live(&[0, 1, 2]),
                live(&[1, 2]),
                live(&[0, 3])
            ]
        );
        assert_eq!(f.turn(0), Turn::Decide { others: vec![] });
        assert_eq!(f.turn(1), Turn::Wait { holder: 0 });
        assert_eq!(f.turn(2), Turn::Wait { holder: 1 }, "2 never heard 0");
        assert_eq!(f.turn(3), Turn::Wait { holder: 0 });
        let (t0, read) = f.pass(0);
        assert_eq!(
            (t0.order.clone(), t0.holder, uavs(&t0.plans)),
            (vec![0, 1, 3], 1, vec![0])
        );
        assert_eq!(read, [0, 1, 3]);
        // 1 and 3 both follow 0: neither heard the other.
        assert_eq!(others(f.turn(1)), [0]);
        assert_eq!(others(f.turn(3)), [0]);
        assert_eq!(f.turn(2), Turn::Wait { holder: 1 });
        let (t3, read) = f.pass(3);
        assert_eq!((t3.holder, uavs(&t3.plans)), (ROUND_COMPLETE, vec![0, 3]));
        assert_eq!(read, [0, 3]);
        let (t1, read) = f.pass(1);
        assert_eq!((t1.holder, uavs(&t1.plans)), (2, vec![0, 1]));
        assert_eq!(read, [0, 1, 2]);
        // 0's plan reaches 2, out of its range, inside 1's token.
        assert_eq!(others(f.turn(2)), [0, 1]);
        let (t2, read) = f.pass(2);
        assert_eq!(
            (t2.holder, uavs(&t2.plans)),
            (ROUND_COMPLETE, vec![0, 1, 2])
        );
        assert_eq!(read, [1, 2]);
        for uav in 0..4 {
            assert_eq!(f.turn(uav), Turn::Done);
        }
        let fleets: Vec<Vec<u32>> = (0..4).map(|u| f.fleet(u)).collect();
        assert_eq!(
            fleets,
            [vec![0, 1, 3], vec![0, 1, 2], vec![1, 2], vec![0, 3]]
        );
    }

    /// Two groups out of each other's range run a chain each, from their lowest UAV; a UAV out
    /// of everyone's range decides at once and nobody waits for it.
    #[test]
    fn a_fleet_split_by_range_runs_one_chain_per_group_and_a_lone_uav_waits_for_none() {
        let positions = [
            (0.0, 0.0),
            (1000.0, 0.0),
            (50.0, 0.0),
            (1050.0, 0.0),
            (-500.0, 500.0),
        ];
        let mut f = RadioFleet::new(&positions, 100.0);
        assert_eq!(f.turn(0), Turn::Decide { others: vec![] });
        assert_eq!(f.turn(1), Turn::Decide { others: vec![] });
        assert_eq!(f.turn(2), Turn::Wait { holder: 0 });
        assert_eq!(f.turn(3), Turn::Wait { holder: 1 });
        assert_eq!(f.turn(4), Turn::Decide { others: vec![] });
        let (lone, read) = f.pass(4);
        assert_eq!((read, lone.holder), (vec![4], ROUND_COMPLETE));
        f.pass(1);
        assert_eq!(
            f.turn(2),
            Turn::Wait { holder: 0 },
            "1's token is not 2's to wait for"
        );
        assert_eq!(others(f.turn(3)), [1]);
        f.pass(3);
        f.pass(0);
        assert_eq!(others(f.turn(2)), [0]);
        f.pass(2);
        assert!((0..5).all(|u| f.turn(u) == Turn::Done));
        assert_eq!(f.fleet(4), [4]);
        assert_eq!(f.fleet(3), [1, 3]);
    }

    /// What an agent decides around is fixed once its waits are over: a token from a UAV it
    /// does not wait for is not used even when it came first, nor passed on; the tokens it
    /// waits for are used whatever order they came in.
    #[test]
    fn under_the_radio_only_the_tokens_waited_for_are_decided_around() {
        // 1 did not hear 0 (its estimate was lost); 2 heard both.
        let lives = [live(&[0, 1, 2]), live(&[1, 2]), live(&[0, 1, 2])];
        let mut rings: Vec<TokenRing> =
            (0..3).map(|i| TokenRing::new(i, Liveness::Radio)).collect();
        let t0 = rings[0].pass(ROUND, STEP, &lives[0], view(0));
        rings[1].receive(t0.clone(), 0, true);
        assert_eq!(
            rings[1].turn(ROUND, &lives[1]),
            Turn::Decide { others: vec![] }
        );
        let t1 = rings[1].pass(ROUND, STEP, &lives[1], view(1));
        assert_eq!(uavs(&t1.plans), [1], "0's plan is not passed on either");
        // 2 reads 1's token first: it still waits for 0's.
        rings[2].receive(t1, 1, true);
        assert_eq!(rings[2].turn(ROUND, &lives[2]), Turn::Wait { holder: 0 });
        rings[2].receive(t0.clone(), 0, true);
        assert_eq!(others(rings[2].turn(ROUND, &lives[2])), [0, 1]);
        // A predecessor's token lost on the way: its sender passed, nothing to wait for.
        let mut lost = TokenRing::new(2, Liveness::Radio);
        lost.receive(t0, 0, false);
        assert_eq!(
            lost.turn(ROUND, &live(&[0, 2])),
            Turn::Decide { others: vec![] }
        );
    }

    /// When every agent hears every other, the radio's reading decides exactly as the world's,
    /// around the same plans, and sends the same tokens.
    #[test]
    fn hearing_everyone_the_two_readings_agree() {
        let all = live(&[0, 1, 2, 3]);
        let run = |liveness: Liveness| {
            let mut rings: Vec<TokenRing> = (0..4).map(|i| TokenRing::new(i, liveness)).collect();
            let mut out = Vec::new();
            for round in [ROUND, ROUND + 1] {
                for uav in 0..4u32 {
                    for other in (0..4).filter(|&o| o != uav) {
                        assert!(matches!(
                            rings[other as usize].turn(round, &all),
                            Turn::Wait { .. } | Turn::Done
                        ));
                    }
                    let turn = rings[uav as usize].turn(round, &all);
                    let fleet = rings[uav as usize].fleet(round, &all);
                    let token = rings[uav as usize].pass(round, STEP, &all, view(uav));
                    for ring in &mut rings {
                        ring.receive(token.clone(), uav, true);
                    }
                    out.push((turn, fleet, token));
                }
            }
            out
        };
        assert_eq!(run(Liveness::Radio), run(Liveness::World));
    }
}
