//! The lock-free UART queue (`ridge_pump_firmware::ring`, the crate's only `unsafe` code),
//! against a `VecDeque` model and with a real producer and consumer on two threads.
//! `cargo +nightly miri test -p ridge-pump-firmware --test ring` also checks it for undefined
//! behaviour and data races (see docs/toolchain.md).

use std::collections::VecDeque;
use std::sync::Arc;

use ridge_pump_firmware::ring::Ring;

/// Capacity is `N − 1`: a full queue refuses the byte and keeps what it holds.
#[test]
fn holds_n_minus_one_bytes_in_order() {
    let q: Ring<8> = Ring::new();
    assert_eq!(q.pop(), None);
    for b in 0..7u8 {
        assert!(q.push(b), "byte {b}");
    }
    assert!(!q.push(99), "full at N − 1");
    for b in 0..7u8 {
        assert_eq!(q.pop(), Some(b));
    }
    assert_eq!(q.pop(), None);
}

/// Any interleaving of pushes and pops behaves like a bounded FIFO (`is_empty` included), across
/// many wrap-arounds of the indices (including the 256-slot queue, whose `u8` indices wrap
/// themselves).
#[test]
fn matches_a_bounded_fifo_model() {
    fn check<const N: usize>(q: &Ring<N>) {
        let mut model = VecDeque::new();
        let (mut full, mut empty) = (0, 0);
        let mut x: u32 = 0x1234_5678;
        let steps: u32 = if cfg!(miri) { 4_000 } else { 200_000 };
        for i in 0..steps {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            // Bias pushes and pops in long phases so the queue runs both full and empty.
            let push = if (i / 1000) % 2 == 0 {
                x % 4 != 0
            } else {
                x % 4 == 0
            };
            if push {
                let b = (x >> 8) as u8;
                let ok = q.push(b);
                assert_eq!(ok, model.len() < N - 1, "push at {i}");
                full += usize::from(!ok);
                if ok {
                    model.push_back(b);
                }
            } else {
                let got = q.pop();
                assert_eq!(got, model.pop_front(), "pop at {i}");
                empty += usize::from(got.is_none());
            }
            assert_eq!(q.is_empty(), model.is_empty(), "is_empty at {i}");
        }
        assert!(
            full > 0 && empty > 0,
            "N = {N}: ran full {full}, empty {empty} times"
        );
    }
    check(&Ring::<2>::new());
    check(&Ring::<16>::new());
    check(&Ring::<256>::new());
}

/// One producer thread and one consumer thread, as the main loop and the transmit interrupt:
/// every byte arrives once, in order, none invented.
#[test]
fn producer_and_consumer_threads_exchange_every_byte_in_order() {
    const BYTES: u32 = if cfg!(miri) { 2_000 } else { 2_000_000 };
    let q = Arc::new(Ring::<64>::new());
    let producer = {
        let q = q.clone();
        std::thread::spawn(move || {
            for i in 0..BYTES {
                while !q.push(i as u8) {
                    std::thread::yield_now();
                }
            }
        })
    };
    let mut next = 0u32;
    while next < BYTES {
        match q.pop() {
            Some(b) => {
                assert_eq!(b, next as u8, "byte {next}");
                next += 1;
            }
            None => std::thread::yield_now(),
        }
    }
    producer.join().unwrap();
    assert_eq!(q.pop(), None);
}

#[test]
fn room_counts_the_free_slots() {
    let ring = Ring::<8>::new();
    assert_eq!(ring.room(), 7);
    for n in 1..=7 {
        assert!(ring.push(n));
        assert_eq!(ring.room(), 7 - usize::from(n));
    }
    assert!(!ring.push(0));
    assert_eq!(ring.pop(), Some(1));
    assert_eq!(ring.room(), 1);
}

/// A receiver that finds the queue full marks the newest byte instead (`replace_newest`): the
/// bytes before it come out unchanged and in order, the marker last; an empty queue is left
/// alone.
#[test]
fn replace_newest_marks_the_last_byte_of_a_full_queue() {
    let q: Ring<8> = Ring::new();
    q.replace_newest(0);
    assert_eq!(q.pop(), None);
    for b in 1..=7u8 {
        assert!(q.push(b));
    }
    assert!(!q.push(8));
    q.replace_newest(0);
    let out: Vec<u8> = std::iter::from_fn(|| q.pop()).collect();
    assert_eq!(out, [1, 2, 3, 4, 5, 6, 0]);
    // After wrapping: the newest slot is the one before `head`, whatever the indices.
    for b in 10..=16u8 {
        assert!(q.push(b));
    }
    q.replace_newest(0);
    let out: Vec<u8> = std::iter::from_fn(|| q.pop()).collect();
    assert_eq!(out, [10, 11, 12, 13, 14, 15, 0]);
}
