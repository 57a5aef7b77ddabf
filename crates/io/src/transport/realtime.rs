//! Real-time scheduling for a station process (Linux `SCHED_FIFO`).
//!
//! A station in user space keeps the line's timing only when it runs at
//! its deadlines. TSYN, the idle time a receiver needs before a request,
//! is 33 bit times: 22 µs at 1.5 Mbit/s, 352 µs at 93.75 kbit/s. An
//! ordinary (`SCHED_OTHER`) process that other processes keep from the
//! CPU reads two telegrams in one piece, so it cannot tell the gap between
//! them, or answers after the slot time. Under `SCHED_FIFO` the kernel
//! runs the process ahead of every ordinary one as soon as it is ready, as
//! PLC runtimes and fieldbus masters on Linux do.
//!
//! It needs root, `CAP_SYS_NICE`, or an `RLIMIT_RTPRIO` (`ulimit -r`) of at
//! least the priority. The kernel's real-time throttling
//! (`/proc/sys/kernel/sched_rt_runtime_us`, 95 % by default) keeps a
//! runaway process from locking up the machine.

use std::io;

/// Why the scheduling policy could not be set.
#[derive(Debug, thiserror::Error)]
pub enum RealtimeError {
    /// The priority is outside `SCHED_FIFO`'s range.
    #[error("real-time priority {0} is outside 1 … 99")]
    Priority(u8),
    /// The kernel refused (`EPERM` without the privilege).
    #[error(
        "SCHED_FIFO priority {priority} refused: {source} (needs root, CAP_SYS_NICE, \
         or `ulimit -r {priority}`)"
    )]
    Refused {
        /// The priority asked for.
        priority: u8,
        /// The kernel's error.
        source: io::Error,
    },
}

/// Run the calling thread under `SCHED_FIFO` at `priority` (1 … 99; keep
/// it below 50, the priority of the kernel's threaded interrupt handlers,
/// so that the serial port's interrupts still run first). Threads it
/// starts afterwards inherit the policy, so call it before a runtime
/// starts its threads.
pub fn set_fifo_priority(priority: u8) -> Result<(), RealtimeError> {
    if !(1..=99).contains(&priority) {
        return Err(RealtimeError::Priority(priority));
    }
    let param = nix::libc::sched_param {
        sched_priority: priority.into(),
    };
    // SAFETY: sched_setscheduler only reads `param`, a valid, initialised
    // struct that lives across the call; pid 0 is the calling thread.
    let r = unsafe { nix::libc::sched_setscheduler(0, nix::libc::SCHED_FIFO, &param) };
    if r != 0 {
        return Err(RealtimeError::Refused {
            priority,
            source: io::Error::last_os_error(),
        });
    }
    Ok(())
}

/// The calling thread's real-time priority: `Some(p)` under `SCHED_FIFO`
/// or `SCHED_RR`, `None` under an ordinary policy.
pub fn fifo_priority() -> Option<u8> {
    // SAFETY: both calls only concern the calling thread (pid 0);
    // sched_getparam writes into `param`, a valid struct owned here.
    let policy = unsafe { nix::libc::sched_getscheduler(0) };
    if policy != nix::libc::SCHED_FIFO && policy != nix::libc::SCHED_RR {
        return None;
    }
    let mut param = nix::libc::sched_param { sched_priority: 0 };
    let r = unsafe { nix::libc::sched_getparam(0, &mut param) };
    (r == 0).then_some(param.sched_priority as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_priority_outside_the_range_is_refused_before_the_kernel_is_asked() {
        assert!(matches!(
            set_fifo_priority(0),
            Err(RealtimeError::Priority(0))
        ));
        assert!(matches!(
            set_fifo_priority(100),
            Err(RealtimeError::Priority(100))
        ));
    }

    #[test]
    fn the_policy_is_set_on_a_thread_of_its_own_or_refused_with_the_reason() {
        // On a thread of its own: the test runner's other threads keep
        // their policy.
        std::thread::spawn(|| match set_fifo_priority(10) {
            Ok(()) => assert_eq!(fifo_priority(), Some(10)),
            Err(RealtimeError::Refused { priority, source }) => {
                assert_eq!(priority, 10);
                assert_eq!(source.raw_os_error(), Some(nix::libc::EPERM));
                assert_eq!(fifo_priority(), None);
            }
            Err(e) => panic!("{e}"),
        })
        .join()
        .unwrap();
    }
}
