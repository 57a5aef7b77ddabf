//! The terminal session the views draw on: raw mode and the alternate
//! screen while it lives, the terminal as it was once it is dropped (also
//! on a panic: ratatui's panic hook restores it first).

use crate::bus::{Action, BusView};
use crate::sniff::SniffView;
use crate::source::BusSource;
use crate::Key;
use profibus_fdl::Instant;
use ratatui::crossterm::event::{self, Event};
use ratatui::{DefaultTerminal, Frame};
use std::io;
use std::time::Duration;

/// A full-screen terminal session on stdout.
pub struct Screen {
    terminal: DefaultTerminal,
}

impl Screen {
    /// Take over the terminal: raw mode (keys arrive one by one, Ctrl-C
    /// as [`Key::Interrupt`]), alternate screen, hidden cursor.
    pub fn open() -> io::Result<Screen> {
        Ok(Screen {
            terminal: ratatui::try_init()?,
        })
    }

    /// Draw one frame.
    pub fn draw(&mut self, render: impl FnOnce(&mut Frame<'_>)) -> io::Result<()> {
        self.terminal.draw(render).map(|_| ())
    }

    /// The keys pressed since the last call, without waiting.
    pub fn keys(&mut self) -> io::Result<Vec<Key>> {
        let mut keys = vec![];
        while event::poll(Duration::ZERO)? {
            if let Event::Key(k) = event::read()? {
                keys.extend(Key::from_crossterm(k));
            }
        }
        Ok(keys)
    }

    /// Wait up to `timeout` for the first key, then take the others that
    /// are already there.
    pub fn keys_within(&mut self, timeout: Duration) -> io::Result<Vec<Key>> {
        if event::poll(timeout)? {
            self.keys()
        } else {
            Ok(vec![])
        }
    }
}

impl Drop for Screen {
    fn drop(&mut self) {
        ratatui::restore();
    }
}

/// A [`BusView`] on the terminal, for an application loop that runs a
/// master or a monitor: keys are read and the screen is drawn at most every
/// [`LiveBus::FRAME`] of wall-clock time, however often the loop calls
/// [`LiveBus::tick`].
pub struct LiveBus {
    screen: Screen,
    view: BusView,
    last_draw: Option<std::time::Instant>,
    last_keys: Option<std::time::Instant>,
}

impl LiveBus {
    /// Time between two frames.
    pub const FRAME: Duration = Duration::from_millis(100);

    /// Time between two looks at the keyboard.
    pub const KEYS: Duration = Duration::from_millis(20);

    /// Take over the terminal for `view`.
    pub fn open(view: BusView) -> io::Result<LiveBus> {
        Ok(LiveBus {
            screen: Screen::open()?,
            view,
            last_draw: None,
            last_keys: None,
        })
    }

    /// The view.
    pub fn view(&self) -> &BusView {
        &self.view
    }

    /// The view.
    pub fn view_mut(&mut self) -> &mut BusView {
        &mut self.view
    }

    /// Read the keys (carrying out writes on `source`), and when a frame
    /// is due take a snapshot of `source` at `now` and draw it.
    /// `Ok(false)`: the person asked to quit.
    pub fn tick<S: BusSource + ?Sized>(
        &mut self,
        source: &mut S,
        now: Instant,
    ) -> io::Result<bool> {
        let wall = std::time::Instant::now();
        let mut redraw = false;
        if self.last_keys.is_none_or(|t| wall - t >= Self::KEYS) {
            self.last_keys = Some(wall);
            for k in self.screen.keys()? {
                redraw = true;
                match self.view.key(k) {
                    Action::Quit => return Ok(false),
                    Action::Write { address, write } => {
                        // The view shows the outcome.
                        let _ = self.view.write(source, address, &write);
                    }
                    Action::None => {}
                }
            }
        }
        if redraw || self.last_draw.is_none_or(|t| wall - t >= Self::FRAME) {
            self.last_draw = Some(wall);
            self.view.update(source, now);
            self.draw()?;
        }
        Ok(true)
    }

    /// Draw the view now.
    pub fn draw(&mut self) -> io::Result<()> {
        let view = &self.view;
        self.screen.draw(|f| view.render(f, f.area()))
    }
}

/// A [`SniffView`] on the terminal: keys are read and the screen drawn
/// at most every [`LiveSniff::FRAME`] of wall-clock time.
pub struct LiveSniff {
    screen: Screen,
    view: SniffView,
    last_draw: Option<std::time::Instant>,
}

impl LiveSniff {
    /// Time between two frames.
    pub const FRAME: Duration = Duration::from_millis(100);

    /// Take over the terminal for `view`.
    pub fn open(view: SniffView) -> io::Result<LiveSniff> {
        Ok(LiveSniff {
            screen: Screen::open()?,
            view,
            last_draw: None,
        })
    }

    /// The view, to feed telegrams to.
    pub fn view_mut(&mut self) -> &mut SniffView {
        &mut self.view
    }

    /// Read the keys and draw when a frame is due. `Ok(false)`: the
    /// person asked to quit.
    pub fn tick(&mut self) -> io::Result<bool> {
        let mut redraw = false;
        for k in self.screen.keys()? {
            redraw = true;
            if self.view.key(k) {
                return Ok(false);
            }
        }
        let wall = std::time::Instant::now();
        if redraw || self.last_draw.is_none_or(|t| wall - t >= Self::FRAME) {
            self.last_draw = Some(wall);
            let view = &self.view;
            self.screen.draw(|f| view.render(f, f.area()))?;
        }
        Ok(true)
    }
}
