//! Single-producer single-consumer byte queue between the main loop and a UART interrupt (the
//! main loop produces for the transmit interrupt and consumes what the receive interrupt
//! produces), so that report lines never stall the 100 Hz loop.
//!
//! Only atomic loads and stores of `u8` indices are used (AVR has no compare-and-swap): the
//! producer alone writes `head`, the consumer alone writes `tail`. One slot stays free to tell a
//! full queue from an empty one, so the capacity is `N − 1` bytes.
//!
//! Why not `heapless::spsc::Queue`: it builds for `avr-none` only with heapless's
//! `portable-atomic` feature, and then costs about the same (+48 B flash, +4 B RAM, 2–6 cycles
//! more per byte); figures in `docs/hand-written.md`.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicU8, Ordering};

/// A byte queue of `N` slots (`N` a power of two, 2 ≤ `N` ≤ 256).
pub struct Ring<const N: usize> {
    buf: UnsafeCell<[u8; N]>,
    /// Next slot the producer writes (owned by the producer).
    head: AtomicU8,
    /// Next slot the consumer reads (owned by the consumer).
    tail: AtomicU8,
}

// SAFETY: a slot is written by the producer only while it is outside `tail..head` (free) and
// read by the consumer only while it is inside (filled); the index stores that move a slot
// between the two sets are Release and are read with Acquire, so the two sides never touch the
// same slot at the same time. There is at most one producer and one consumer (documented on
// `push` and `pop`).
unsafe impl<const N: usize> Sync for Ring<N> {}

impl<const N: usize> Default for Ring<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Ring<N> {
    const MASK: u8 = {
        assert!(N.is_power_of_two() && N >= 2 && N <= 256);
        (N - 1) as u8
    };

    /// An empty queue.
    pub const fn new() -> Self {
        Ring {
            buf: UnsafeCell::new([0; N]),
            head: AtomicU8::new(0),
            tail: AtomicU8::new(0),
        }
    }

    /// Appends `byte`; `false` if the queue is full. Producer side only (one context).
    pub fn push(&self, byte: u8) -> bool {
        let head = self.head.load(Ordering::Relaxed);
        let next = head.wrapping_add(1) & Self::MASK;
        if next == self.tail.load(Ordering::Acquire) {
            return false;
        }
        // SAFETY: slot `head` is free (not in tail..head) and only the producer writes free
        // slots; see the `Sync` impl.
        unsafe { (*self.buf.get())[usize::from(head & Self::MASK)] = byte };
        self.head.store(next, Ordering::Release);
        true
    }

    /// Producer only, on a full queue: overwrites the newest byte (a receiver marks lost
    /// bytes there). Does nothing on an empty queue. The consumer reads the oldest byte, which
    /// on a full queue of `N ≥ 4` is not the newest.
    pub fn replace_newest(&self, byte: u8) {
        let head = self.head.load(Ordering::Relaxed);
        if head == self.tail.load(Ordering::Acquire) {
            return;
        }
        let newest = head.wrapping_sub(1) & Self::MASK;
        // SAFETY: slot `newest` is written by the producer only; the consumer is at `tail`,
        // another slot unless the queue holds one byte (then it may read the old or new value).
        unsafe { (*self.buf.get())[usize::from(newest)] = byte };
    }

    /// Free slots: bytes that [`push`](Self::push) would take now. Producer side only.
    pub fn room(&self) -> usize {
        let head = self.head.load(Ordering::Relaxed);
        let tail = self.tail.load(Ordering::Acquire);
        usize::from(tail.wrapping_sub(head).wrapping_sub(1) & Self::MASK)
    }

    /// Whether the queue holds no byte. Consumer side only.
    pub fn is_empty(&self) -> bool {
        self.tail.load(Ordering::Relaxed) == self.head.load(Ordering::Acquire)
    }

    /// Removes the oldest byte. Consumer side only (one context, e.g. the TX interrupt).
    pub fn pop(&self) -> Option<u8> {
        let tail = self.tail.load(Ordering::Relaxed);
        if tail == self.head.load(Ordering::Acquire) {
            return None;
        }
        // SAFETY: slot `tail` is filled and only the consumer reads filled slots.
        // (`& MASK` changes no index, all are below `N`: it lets the compiler drop the bounds
        // check and its panic path.)
        let byte = unsafe { (*self.buf.get())[usize::from(tail & Self::MASK)] };
        self.tail
            .store(tail.wrapping_add(1) & Self::MASK, Ordering::Release);
        Some(byte)
    }
}
