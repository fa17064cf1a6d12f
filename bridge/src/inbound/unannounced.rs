//! Messages of remote processes that came before the process was announced alive.
//!
//! A host announces a process (a Zenoh liveliness token) before it forwards anything of it,
//! but Zenoh does not order a liveliness token against data: a bridge that joins while the
//! tokens exist learns of them from a history query, whose answer may come after the data
//! that followed them. Published at once, such a message (an agent's first hello, say) would
//! reach a local process that then lists the run's nodes and finds its sender dead. So the
//! inbound thread holds a sender's messages, in their order, until its proxy exists.
//!
//! Holding never loses a message: after [`HOLD`], or once a sender's held messages pass
//! [`HOLD_BYTES`], they are published anyway, as they were before holding existed (a sender
//! whose announcement never comes, or one announced gone while its last messages were on
//! the way).

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use crate::keys::Topic;

/// Longest wait of a message for its sender's announcement.
pub const HOLD: Duration = Duration::from_secs(2);
/// Most payload bytes held for one sender (a few frames).
pub const HOLD_BYTES: usize = 8 << 20;

/// A message: what it is and its bytes.
pub type Message = (Topic, Vec<u8>);

/// One sender's held messages, oldest first.
struct Held {
    /// When the oldest came.
    since: Instant,
    bytes: usize,
    messages: VecDeque<Message>,
}

/// The held messages, by sender node.
#[derive(Default)]
pub struct Unannounced {
    senders: BTreeMap<String, Held>,
}

impl Unannounced {
    /// Holds a message of `sender` that came at `now`. Returns the sender's messages, oldest
    /// first, when they now pass [`HOLD_BYTES`] (they are no longer held); else nothing.
    pub fn hold(&mut self, sender: &str, message: Message, now: Instant) -> Vec<Message> {
        let held = self.senders.entry(sender.to_owned()).or_insert(Held {
            since: now,
            bytes: 0,
            messages: VecDeque::new(),
        });
        held.bytes += message.1.len();
        held.messages.push_back(message);
        if held.bytes > HOLD_BYTES {
            self.release(sender)
        } else {
            Vec::new()
        }
    }

    /// Whether messages of `sender` are held (a later one must wait behind them).
    pub fn holds(&self, sender: &str) -> bool {
        self.senders.contains_key(sender)
    }

    /// Every held message of `sender`, oldest first; none are held afterwards.
    pub fn release(&mut self, sender: &str) -> Vec<Message> {
        self.senders
            .remove(sender)
            .map(|h| h.messages.into())
            .unwrap_or_default()
    }

    /// The messages of every sender whose oldest has waited [`HOLD`] by `now`, each sender's
    /// oldest first.
    pub fn expired(&mut self, now: Instant) -> Vec<Message> {
        let due: Vec<String> = self
            .senders
            .iter()
            .filter(|(_, h)| now.duration_since(h.since) >= HOLD)
            .map(|(s, _)| s.clone())
            .collect();
        due.iter().flat_map(|s| self.release(s)).collect()
    }

    /// Every held message, each sender's oldest first.
    pub fn release_all(&mut self) -> Vec<Message> {
        std::mem::take(&mut self.senders)
            .into_values()
            .flat_map(|h| h.messages)
            .collect()
    }

    /// When the next sender's hold ends, if any is held.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.senders.values().map(|h| h.since + HOLD).min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(uav: u32, byte: u8, len: usize) -> Message {
        (Topic::Command(uav), vec![byte; len])
    }

    #[test]
    fn a_senders_messages_come_out_in_order_when_it_is_announced() {
        let t0 = Instant::now();
        let mut u = Unannounced::default();
        assert!(u.hold("agent-3", msg(3, 1, 4), t0).is_empty());
        assert!(u.hold("agent-2", msg(2, 9, 4), t0).is_empty());
        assert!(u.hold("agent-3", msg(3, 2, 4), t0).is_empty());
        assert!(u.holds("agent-3"));
        let out = u.release("agent-3");
        assert_eq!(out, vec![msg(3, 1, 4), msg(3, 2, 4)]);
        assert!(!u.holds("agent-3"));
        assert!(u.release("agent-3").is_empty());
        assert_eq!(u.release_all(), vec![msg(2, 9, 4)]);
        assert_eq!(u.next_deadline(), None);
    }

    #[test]
    fn messages_waiting_too_long_or_too_big_are_given_up_never_dropped() {
        let t0 = Instant::now();
        let mut u = Unannounced::default();
        u.hold("agent-1", msg(1, 1, 4), t0);
        u.hold("agent-2", msg(2, 2, 4), t0 + HOLD / 2);
        assert_eq!(u.next_deadline(), Some(t0 + HOLD));
        assert!(u.expired(t0 + HOLD / 2).is_empty());
        assert_eq!(u.expired(t0 + HOLD), vec![msg(1, 1, 4)]);
        assert_eq!(u.next_deadline(), Some(t0 + HOLD / 2 + HOLD));
        // Past the byte budget, the sender's messages all come out, oldest first.
        let big = HOLD_BYTES / 2 + 1;
        assert!(u.hold("agent-2", msg(2, 3, big), t0).is_empty());
        let out = u.hold("agent-2", msg(2, 4, big), t0);
        assert_eq!(out, vec![msg(2, 2, 4), msg(2, 3, big), msg(2, 4, big)]);
        assert!(!u.holds("agent-2"));
    }
}
