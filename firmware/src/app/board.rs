//! What the 100 Hz loop ([`super::App`]) needs from a board besides sensor, pump and UART:
//! the tick, the watchdog, the record store, the stack figures and the console's bytes.

use super::Console;

/// What the loop needs from a board besides sensor, pump and UART.
pub trait Board {
    /// Whether the loop keeps ticking (sensor, state machine, pump, events) from the search's
    /// `pet` calls, through [`SelfIdentification::take_search`]. That costs a copy of the
    /// estimation statistics and the tick's stack on top of the search's deepest frame, which
    /// the ATmega2560's 8 KB do not have; without it the blocking
    /// [`SelfIdentification::search`] runs and the PWM holds the base duty meanwhile, with
    /// the sensor read and the fault checks ([`SelfIdentification::guard`]) at every tick
    /// boundary.
    ///
    /// [`SelfIdentification::take_search`]: crate::selfid::SelfIdentification::take_search
    /// [`SelfIdentification::search`]: crate::selfid::SelfIdentification::search
    /// [`SelfIdentification::guard`]: crate::selfid::SelfIdentification::guard
    const TICK_DURING_SEARCH: bool;
    /// Non-blocking: the number of 10 ms tick boundaries that passed since the last call that
    /// returned `Some` (≥ 1), or `None` if none did.
    fn poll_tick(&mut self) -> Option<u16>;
    /// Restarts the watchdog's timeout.
    fn pet(&mut self);
    /// Stores `record` (the board may finish the write later, see [`poll_store`]).
    ///
    /// [`poll_store`]: Board::poll_store
    fn save(&mut self, record: &[u8]);
    /// Advances a pending write; `Some(ok)` once when a write finished.
    fn poll_store(&mut self) -> Option<bool>;
    /// Stack high-water mark `(used, free)` in bytes, if the board measures it.
    fn stack(&self) -> Option<(u16, u16)>;
    /// Non-blocking: the next received console byte, if any.
    fn receive(&mut self) -> Option<u8> {
        None
    }
    /// Whether received bytes were lost since the last call (the receive queue was full). A
    /// board that marks the place in its queue instead ([`crate::command::LOST`], the
    /// ATmega2560) keeps the default `false`.
    fn receive_overrun(&mut self) -> bool {
        false
    }
    /// Free bytes in the transmit queue: a log row is sent only if it fits whole.
    fn tx_room(&self) -> usize {
        usize::MAX
    }
    /// The console's state, if the board has a console (receives commands). `None` leaves
    /// the console code out of the image.
    fn console(&mut self) -> Option<&mut Console> {
        None
    }
}
