//! What a bridge forwarded, refused and announced: counted by each of its threads and merged
//! into the report it prints at exit.

use std::collections::BTreeMap;

use serde::Serialize;

/// Messages and bytes of one kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Flow {
    /// Messages.
    pub messages: u64,
    /// Payload bytes.
    pub bytes: u64,
}

/// The counters of one thread, or of the whole bridge once merged.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    /// Sent to other hosts, by kind (`frame`, `command`, `estimate`, `state`, `token`,
    /// `end_of_run`).
    pub sent: BTreeMap<String, Flow>,
    /// Received from other hosts and published here, by kind.
    pub received: BTreeMap<String, Flow>,
    /// Received and refused, by `kind:reason`.
    pub refused: BTreeMap<String, u64>,
    /// Messages this host's processes published that could not be sent, by kind.
    pub send_failures: BTreeMap<String, u64>,
    /// Proxy nodes made for remote processes announced alive.
    pub proxies_created: u64,
    /// Liveliness tokens declared for this host's processes.
    pub announced: u64,
    /// Messages of remote processes that came before the process's announcement, and waited
    /// for it.
    pub held: u64,
    /// Of those, the messages published without it: it did not come within the wait, or the
    /// sender's held messages outgrew the hold.
    pub unannounced: u64,
}

impl Counters {
    /// Counts a message sent.
    pub fn sent(&mut self, kind: &str, bytes: u64) {
        add(&mut self.sent, kind, bytes);
    }

    /// Counts a message received and published.
    pub fn received(&mut self, kind: &str, bytes: u64) {
        add(&mut self.received, kind, bytes);
    }

    /// Counts a refused message.
    pub fn refused(&mut self, kind: &str, reason: &str) {
        *self.refused.entry(format!("{kind}:{reason}")).or_default() += 1;
    }

    /// Counts a message that could not be sent.
    pub fn send_failed(&mut self, kind: &str) {
        *self.send_failures.entry(kind.to_owned()).or_default() += 1;
    }

    /// Adds another thread's counters.
    pub fn merge(&mut self, other: Counters) {
        for (map, theirs) in [
            (&mut self.sent, other.sent),
            (&mut self.received, other.received),
        ] {
            for (k, f) in theirs {
                let mine = map.entry(k).or_default();
                mine.messages += f.messages;
                mine.bytes += f.bytes;
            }
        }
        for (map, theirs) in [
            (&mut self.refused, other.refused),
            (&mut self.send_failures, other.send_failures),
        ] {
            for (k, n) in theirs {
                *map.entry(k).or_default() += n;
            }
        }
        self.proxies_created += other.proxies_created;
        self.announced += other.announced;
        self.held += other.held;
        self.unannounced += other.unannounced;
    }

    /// Messages refused in all.
    pub fn refused_total(&self) -> u64 {
        self.refused.values().sum()
    }
}

fn add(map: &mut BTreeMap<String, Flow>, kind: &str, bytes: u64) {
    let flow = map.entry(kind.to_owned()).or_default();
    flow.messages += 1;
    flow.bytes += bytes;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_counters_add_up() {
        let mut a = Counters::default();
        a.sent("frame", 10);
        a.refused("estimate", "malformed");
        let mut b = Counters::default();
        b.sent("frame", 5);
        b.received("token", 3);
        b.refused("estimate", "malformed");
        b.proxies_created = 2;
        b.held = 3;
        b.unannounced = 1;
        a.merge(b);
        assert_eq!(
            a.sent["frame"],
            Flow {
                messages: 2,
                bytes: 15
            }
        );
        assert_eq!(a.received["token"].messages, 1);
        assert_eq!(a.refused_total(), 2);
        assert_eq!(a.proxies_created, 2);
        assert_eq!((a.held, a.unannounced), (3, 1));
    }
}
