//! The round-robin guidance token, as a state machine that does no I/O.
//!
//! One round per guidance period. The lowest live UAV issues the token, plans first and
//! passes it; each next UAV in the round's order plans around the plans already in it, appends
//! its own and passes it on. Every agent sees every token sent (the guidance service is
//! all-to-all), so each knows how far the round got. A round never stalls the fleet:
//! - a holder that is known dead is skipped at once: the next live UAV in the order after it
//!   takes the turn and reissues the token with the plans gathered so far;
//! - a holder that stays silent longer than the agent's bounded wait is treated the same way
//!   by whoever waits for it (the caller says so with `waited_out`).
//!
//! An agent decides at most once per round; a late duplicate token only adds plans.
//! (docs/design.md says the lowest live UAV reissues a lost token; reissuing by the next live UAV
//! in the order keeps the round's order and loses no plan, and is the same UAV whenever the
//! first holder is the one that died.)

use std::collections::BTreeSet;

use protocol::wire::{GuidanceToken, PlannedView};

/// Holder value of a token whose round is complete.
pub const ROUND_COMPLETE: u32 = u32::MAX;

/// What the agent should do about the current round.
#[derive(Clone, Debug, PartialEq)]
pub enum Turn {
    /// Someone before this agent has not decided yet: wait (bounded).
    Wait {
        /// The UAV expected to act.
        holder: u32,
    },
    /// Decide now, planning around these plans.
    Decide {
        /// Plans of the UAVs that decided before.
        others: Vec<PlannedView>,
    },
    /// This agent already decided this round.
    Done,
}

/// One agent's view of the token ring.
#[derive(Clone, Debug)]
pub struct TokenRing {
    me: u32,
    decided_round: Option<u64>,
    latest: Option<GuidanceToken>,
    /// Tokens dropped because they belonged to an older round.
    pub stale_tokens: u64,
}

impl TokenRing {
    /// The ring as seen by UAV `me`.
    pub fn new(me: u32) -> Self {
        Self {
            me,
            decided_round: None,
            latest: None,
            stale_tokens: 0,
        }
    }

    /// Takes note of a token seen on the guidance service (including this agent's own).
    pub fn observe(&mut self, token: GuidanceToken) {
        let keep = match &self.latest {
            None => true,
            Some(cur) => {
                token.round > cur.round
                    || (token.round == cur.round && token.plans.len() >= cur.plans.len())
            }
        };
        if keep {
            self.latest = Some(token);
        } else {
            self.stale_tokens += 1;
        }
    }

    fn latest_of(&self, round: u64) -> Option<&GuidanceToken> {
        self.latest.as_ref().filter(|t| t.round == round)
    }

    /// What to do in `round`, given the UAVs this agent believes live (itself included) and
    /// whether its bounded wait for the holder has run out.
    pub fn turn(&self, round: u64, live: &BTreeSet<u32>, waited_out: bool) -> Turn {
        if self.decided_round == Some(round) {
            return Turn::Done;
        }
        let token = self.latest_of(round);
        let others = token.map(|t| t.plans.clone()).unwrap_or_default();
        if waited_out {
            return Turn::Decide { others };
        }
        let expected = match token {
            None => live.iter().copied().next().unwrap_or(self.me),
            Some(t) => self.next_live_holder(t, live),
        };
        if expected == self.me {
            Turn::Decide { others }
        } else {
            Turn::Wait { holder: expected }
        }
    }

    /// The holder of `t`, or if it is dead, the next live UAV in the order that has not
    /// decided; this agent when nobody else qualifies.
    fn next_live_holder(&self, t: &GuidanceToken, live: &BTreeSet<u32>) -> u32 {
        if t.holder == ROUND_COMPLETE || live.contains(&t.holder) {
            // A complete round that this agent has not decided in means it joined late: act.
            return if t.holder == ROUND_COMPLETE {
                self.me
            } else {
                t.holder
            };
        }
        let decided: BTreeSet<u32> = t.plans.iter().map(|p| p.uav).collect();
        let start = t.order.iter().position(|&u| u == t.holder).unwrap_or(0);
        t.order
            .iter()
            .skip(start)
            .copied()
            .find(|u| live.contains(u) && !decided.contains(u))
            .unwrap_or(self.me)
    }

    /// Records this agent's decision for `round` (started at `step`) and returns the token to
    /// publish: the round's latest token (or a new one issued by this agent) with `view`
    /// appended and the next live UAV of the order as holder.
    pub fn pass(
        &mut self,
        round: u64,
        step: u64,
        live: &BTreeSet<u32>,
        view: PlannedView,
    ) -> GuidanceToken {
        let mut token = match self.latest_of(round) {
            Some(t) => t.clone(),
            None => GuidanceToken {
                round,
                step,
                order: live.iter().copied().collect(),
                holder: self.me,
                issued_by: self.me,
                plans: Vec::new(),
            },
        };
        if token.holder != self.me {
            // Taking over from a dead or silent holder: this agent reissues the token.
            token.issued_by = self.me;
        }
        if !token.order.contains(&self.me) {
            token.order.push(self.me);
        }
        token.plans.retain(|p| p.uav != self.me);
        token.plans.push(view);
        let decided: BTreeSet<u32> = token.plans.iter().map(|p| p.uav).collect();
        let my_pos = token.order.iter().position(|&u| u == self.me).unwrap_or(0);
        token.holder = token
            .order
            .iter()
            .skip(my_pos + 1)
            .chain(token.order.iter().take(my_pos))
            .copied()
            .find(|u| live.contains(u) && !decided.contains(u))
            .unwrap_or(ROUND_COMPLETE);
        self.decided_round = Some(round);
        self.latest = Some(token.clone());
        token
    }
}

#[cfg(test)]
mod tests {
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

    #[test]
    fn a_round_visits_every_live_uav_in_order() {
        let all = live(&[0, 1, 2]);
        let mut rings: Vec<TokenRing> = (0..3).map(TokenRing::new).collect();
        assert_eq!(rings[1].turn(5, &all, false), Turn::Wait { holder: 0 });
        assert_eq!(
            rings[0].turn(5, &all, false),
            Turn::Decide { others: vec![] }
        );
        let t = rings[0].pass(5, 30, &all, view(0));
        assert_eq!(t.holder, 1);
        for r in &mut rings {
            r.observe(t.clone());
        }
        assert_eq!(rings[0].turn(5, &all, false), Turn::Done);
        assert_eq!(rings[2].turn(5, &all, false), Turn::Wait { holder: 1 });
        assert_eq!(
            rings[1].turn(5, &all, false),
            Turn::Decide {
                others: vec![view(0)]
            }
        );
        let t = rings[1].pass(5, 30, &all, view(1));
        rings[2].observe(t);
        let t = match rings[2].turn(5, &all, false) {
            Turn::Decide { others } => {
                assert_eq!(others.len(), 2);
                rings[2].pass(5, 30, &all, view(2))
            }
            other => panic!("{other:?}"),
        };
        assert_eq!(t.holder, ROUND_COMPLETE);
        assert_eq!(t.plans.len(), 3);
    }

    #[test]
    fn a_dead_holder_is_skipped_at_once() {
        let mut r2 = TokenRing::new(2);
        let mut r0 = TokenRing::new(0);
        let t = r0.pass(1, 6, &live(&[0, 1, 2]), view(0));
        assert_eq!(t.holder, 1);
        r2.observe(t);
        // UAV 1 died while holding the token.
        assert_eq!(
            r2.turn(1, &live(&[0, 2]), false),
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
        let r1 = TokenRing::new(1);
        assert_eq!(
            r1.turn(0, &live(&[1, 2]), false),
            Turn::Decide { others: vec![] }
        );
        let r2 = TokenRing::new(2);
        assert_eq!(r2.turn(0, &live(&[1, 2]), false), Turn::Wait { holder: 1 });
    }

    #[test]
    fn a_silent_holder_is_bypassed_after_the_wait() {
        let r2 = TokenRing::new(2);
        assert_eq!(
            r2.turn(3, &live(&[0, 1, 2]), true),
            Turn::Decide { others: vec![] }
        );
    }

    #[test]
    fn old_tokens_do_not_replace_newer_ones() {
        let mut r = TokenRing::new(3);
        let mut a = TokenRing::new(0);
        let t2 = a.pass(2, 12, &live(&[0, 3]), view(0));
        let mut b = TokenRing::new(0);
        let t1 = b.pass(1, 6, &live(&[0, 3]), view(0));
        r.observe(t2);
        r.observe(t1);
        assert_eq!(r.stale_tokens, 1);
        assert_eq!(
            r.turn(2, &live(&[0, 3]), false),
            Turn::Decide {
                others: vec![view(0)]
            }
        );
    }
}
