//! One connection's work from a driver's tick: [`Class2Run`] opens a
//! connection, hands the requests of a [`RecordOps`] to it one at a
//! time, and closes it (Abort, instance user) after the last answer.

use super::{Class2Error, Class2Event, Class2Master, ConnId, Opened, RecordOps};
use profibus_fdl::time::Instant;
use std::ops::ControlFlow;

/// Runs a [`RecordOps`] on one connection to `slave`; see the module
/// docs.
#[derive(Debug)]
pub struct Class2Run<O> {
    ops: O,
    slave: u8,
    conn: Option<ConnId>,
    opened: Option<Opened>,
    error: Option<Class2Error>,
    closing: bool,
    done: bool,
}

impl<O: RecordOps> Class2Run<O> {
    /// Run `ops` on a connection to `slave`.
    pub fn new(slave: u8, ops: O) -> Class2Run<O> {
        Class2Run {
            ops,
            slave,
            conn: None,
            opened: None,
            error: None,
            closing: false,
            done: false,
        }
    }

    /// One tick: `Break` once the connection is closed.
    pub fn tick(&mut self, m: &mut Class2Master, now: Instant) -> ControlFlow<()> {
        let conn = *self.conn.get_or_insert_with(|| m.connect(self.slave, now));
        m.handle_time(now);
        while let Some(event) = m.poll_event() {
            match event {
                Class2Event::Opened { conn: c, info, .. } if c == conn => {
                    self.opened = Some(info);
                    self.next(m, conn);
                }
                Class2Event::Answer {
                    conn: c,
                    op,
                    answer,
                    ..
                } if c == conn => {
                    self.ops.answered(&op, &answer);
                    self.next(m, conn);
                }
                Class2Event::Closed { conn: c, error, .. } if c == conn => {
                    self.error = self.error.take().or(error);
                    self.done = true;
                }
                _ => {}
            }
        }
        if self.done {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    }

    fn next(&mut self, m: &mut Class2Master, conn: ConnId) {
        if self.closing {
            return;
        }
        match self.ops.next_op().map(|op| m.request(conn, op)) {
            Some(Ok(())) => {}
            Some(Err(e)) => {
                self.error = Some(e);
                self.closing = true;
                m.close(conn);
            }
            None => {
                self.closing = true;
                m.close(conn);
            }
        }
    }

    /// The Initiate.res, once the connection was open.
    pub fn opened(&self) -> Option<&Opened> {
        self.opened.as_ref()
    }

    /// The requests and their answers so far.
    pub fn ops(&self) -> &O {
        &self.ops
    }

    /// The requests, or why the connection failed (the answers before
    /// the failure stay in [`Class2Run::ops`]).
    pub fn finish(self) -> Result<O, (Class2Error, O)> {
        match self.error {
            Some(e) => Err((e, self.ops)),
            None => Ok(self.ops),
        }
    }
}
