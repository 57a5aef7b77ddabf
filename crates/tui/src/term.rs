//! The terminal session the views draw on: raw mode and the alternate
//! screen while it lives, the terminal as it was once it is dropped (also
//! on a panic: ratatui's panic hook restores it first).

use crate::Key;
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
