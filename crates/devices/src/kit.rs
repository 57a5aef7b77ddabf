//! Parts every emulated device shares: its queue of device events and
//! the schedule on which it reads its control inbox.

use crate::ControlInbox;
use profibus_dp::slave::DeviceEvent;
use profibus_fdl::Instant;
use std::collections::VecDeque;
use std::time::Duration;

/// How often a device looks at its control inbox (bus time).
pub(crate) const INBOX_PERIOD: Duration = Duration::from_millis(20);

/// Device events waiting for [`Device::poll_event`]; beyond `limit`
/// waiting events new ones are dropped (nobody is reading them).
///
/// [`Device::poll_event`]: profibus_dp::slave::Device::poll_event
#[derive(Debug, Clone)]
pub(crate) struct EventQueue {
    events: VecDeque<DeviceEvent>,
    limit: usize,
}

impl Default for EventQueue {
    /// At most 64 waiting events.
    fn default() -> EventQueue {
        EventQueue::with_limit(64)
    }
}

impl EventQueue {
    /// A queue keeping at most `limit` waiting events.
    pub(crate) fn with_limit(limit: usize) -> EventQueue {
        EventQueue {
            events: VecDeque::new(),
            limit,
        }
    }

    /// Queue an event of `kind` (and log it).
    pub(crate) fn note(&mut self, kind: &'static str, text: String) {
        tracing::debug!(kind, %text, "device event");
        if self.events.len() < self.limit {
            self.events.push_back(DeviceEvent { kind, text });
        }
    }

    /// The oldest waiting event.
    pub(crate) fn pop(&mut self) -> Option<DeviceEvent> {
        self.events.pop_front()
    }

    /// Drop every waiting event.
    #[cfg(test)]
    pub(crate) fn clear(&mut self) {
        self.events.clear();
    }
}

/// A device's control inbox, looked at every [`INBOX_PERIOD`].
#[derive(Debug, Default)]
pub(crate) struct InboxSchedule {
    inbox: Option<ControlInbox>,
    next: Instant,
}

impl InboxSchedule {
    /// Read commands from `inbox` (from now on).
    pub(crate) fn set(&mut self, inbox: ControlInbox) {
        self.inbox = Some(inbox);
    }

    /// When the inbox is looked at next (for [`Device::poll_timeout`]);
    /// `None` without an inbox.
    ///
    /// [`Device::poll_timeout`]: profibus_dp::slave::Device::poll_timeout
    pub(crate) fn deadline(&self) -> Option<Instant> {
        self.inbox.as_ref().map(|_| self.next)
    }

    /// The command lines waiting at `now` (trimmed; empty lines skipped)
    /// when it is time to look, and then the next look is one
    /// [`INBOX_PERIOD`] later; no lines before that time.
    pub(crate) fn due(&mut self, now: Instant) -> DueLines {
        match &self.inbox {
            Some(inbox) if now >= self.next => {
                self.next = now + INBOX_PERIOD;
                DueLines(Some(inbox.clone()))
            }
            _ => DueLines(None),
        }
    }
}

/// The lines [`InboxSchedule::due`] hands out.
pub(crate) struct DueLines(Option<ControlInbox>);

impl Iterator for DueLines {
    type Item = String;

    fn next(&mut self) -> Option<String> {
        loop {
            let mut line = self.0.as_ref()?.take()?;
            line.truncate(line.trim_end().len());
            let blank = line.len() - line.trim_start().len();
            line.drain(..blank);
            if !line.is_empty() {
                return Some(line);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inbox_lines_come_trimmed_once_per_period() {
        let inbox = ControlInbox::new();
        let mut s = InboxSchedule::default();
        assert_eq!(s.deadline(), None);
        assert_eq!(s.due(Instant::ZERO).count(), 0);
        s.set(inbox.clone());
        assert_eq!(s.deadline(), Some(Instant::ZERO));
        inbox.push("  status \r");
        inbox.push("   ");
        inbox.push("get 5");
        let t = Instant::ZERO + Duration::from_millis(3);
        assert_eq!(s.due(t).collect::<Vec<_>>(), ["status", "get 5"]);
        assert_eq!(s.deadline(), Some(t + INBOX_PERIOD));
        inbox.push("later");
        assert_eq!(s.due(t + Duration::from_millis(19)).count(), 0);
        assert_eq!(s.due(t + INBOX_PERIOD).collect::<Vec<_>>(), ["later"]);
    }

    #[test]
    fn events_beyond_the_limit_are_dropped() {
        let mut q = EventQueue::with_limit(2);
        for i in 0..3 {
            q.note("x", i.to_string());
        }
        assert_eq!(q.pop().map(|e| e.text), Some("0".into()));
        assert_eq!(q.pop().map(|e| e.text), Some("1".into()));
        assert_eq!(q.pop(), None);
    }
}
