//! Measurement image for the ATmega2560 (diagnostics, not flashed by users): runs one of the
//! project's hand-written routines, or the crate that would replace it, on fixed inputs and
//! prints the results over USART0 (115 200 baud, polled). `docs/hand-written.md` has the figures
//! and `scripts/avr-bench` makes them.
//!
//! The routine is chosen at compile time by the environment variable `AVR_BENCH`: one image per
//! variant, so that each image's flash and static RAM minus those of the `empty` image is what
//! the routine (and its few lines of measurement glue) adds. Unset, it is `all`: every variant
//! that fits in one image, a quick check only (inlining and register allocation differ in the
//! shared image, which moves the cycle counts by a few percent). Every image first times the
//! bare call of `empty`. The comparison crates come with the cargo feature `bench-crates`:
//!
//! | variant | routine |
//! |---|---|
//! | `empty` | nothing: the call, marker and printing overhead the others are measured against |
//! | `chol-ours` | ridge-core's packed Cholesky (its own `cholesky.rs`), 12 × 12 and 13 × 13 |
//! | `chol-nalgebra12`, `chol-nalgebra13` | `nalgebra::Cholesky` on an `SMatrix<f32, N, N>` |
//! | `sqrt-ours`, `sqrt-nalgebra` | the `f32` square root each of them takes per pivot |
//! | `eig-ours` | ridge-core's one-sided Jacobi (its `eigen.rs`) on a factor `M`, 8 and 12 columns |
//! | `eig-nalgebra8`, `eig-nalgebra12` | `nalgebra::SymmetricEigen` of `M Mᵀ` formed in `f32` |
//! | `eig-svd8`, `eig-svd12` | `nalgebra::SVD` of `M` (left singular vectors: the eigenvectors) |
//! | `ring-ours` | `ridge_pump_firmware::ring::Ring<256>` |
//! | `ring-heapless08`, `ring-heapless09` | `heapless::spsc::Queue<u8, 256>` (0.8 / 0.9) |
//! | `crc8-ours` | `ridge_pump_firmware::sfm3300::crc8` |
//! | `crc8-notable`, `crc8-table1`, `crc8-table16` | `crc::Crc<u8, NoTable / Table<1> / Table<16>>` |
//! | `crc32-ours` | `ridge_pump_firmware::persist::crc32` |
//! | `crc32-notable`, `crc32-table1`, `crc32-table16` | `crc::Crc<u32, …>`, `CRC_32_ISO_HDLC` |
//! | `fmt-ours` | `ridge_pump_firmware::numfmt::Fixed` with `ufmt` |
//! | `fmt-ufmt-float` | `ufmt_float::uFmt_f32::Four` with `ufmt` |
//! | `fmt-core` | `core::fmt`'s `{:.4}` |
//! | `reid-ours` | `ridge_core::reid` at 9 coefficients: a tick's `Window::push`, a breath's `end_breath`, `Refit::start` (and its parts `begin`, `take_rows`, `take_responses`), and each unit of `Refit::step` (factor rows, solution, 3 iterates) |
//!
//! Protocol (read by `simavr-harness`'s `avr-bench`): for each measurement the image prints
//! `M <variant> <label>`, raises PB7 (Arduino pin 13), calls the routine (`#[inline(never)]`),
//! lowers PB7 and completes the line with the routine's results (` <word>…` and a newline). The
//! timed routines are the `#[inline(never)]` functions named `<family>_<variant>` (`chol_ours`,
//! `push_heapless08`, `crc32_table1`, …), which the host finds in the disassembly to size. The
//! host takes the cycles between the two edges from simavr's cycle counter and the stack depth
//! from SRAM it paints below the stack pointer at the rising edge. The image ends with `DONE`
//! and `cli; sleep`.
#![cfg_attr(target_arch = "avr", no_std, no_main)]

#[cfg(not(target_arch = "avr"))]
fn main() {
    eprintln!("avr-bench is a board image: build it for avr-none (scripts/avr-bench)");
    std::process::exit(2);
}

// ridge-core's Cholesky is crate-private: compile its very source file here, with the two
// names it takes from its crate (`crate::error`, `crate::real`) re-exported from ridge-core.
#[cfg(target_arch = "avr")]
mod error {
    pub use ridge_core::error::{Error, Result};
}
#[cfg(target_arch = "avr")]
mod real {
    pub use ridge_core::Real;
}
#[cfg(target_arch = "avr")]
#[allow(dead_code)]
#[path = "../../../ridge-core/src/cholesky.rs"]
mod cholesky;
// ... and its eigen-decomposition, which also takes the crate's maxima.
#[cfg(target_arch = "avr")]
use ridge_core::{PARAMS_MAX, P_MAX, Q_MAX};
#[cfg(target_arch = "avr")]
#[allow(dead_code)]
#[path = "../../../ridge-core/src/eigen.rs"]
mod eigen;

#[cfg(target_arch = "avr")]
mod image {
    use avr_device::atmega2560 as pac;
    use core::hint::black_box;
    use core::panic::PanicInfo;
    use core::ptr::write_volatile;
    use core::sync::atomic::{compiler_fence, Ordering};
    use ufmt::{uWrite, uwrite};

    /// The variant, from `AVR_BENCH` at build time.
    const VARIANT: &str = match option_env!("AVR_BENCH") {
        Some(v) => v,
        None => "all",
    };

    const fn same(a: &str, b: &str) -> bool {
        let (a, b) = (a.as_bytes(), b.as_bytes());
        if a.len() != b.len() {
            return false;
        }
        let mut i = 0;
        while i < a.len() {
            if a[i] != b[i] {
                return false;
            }
            i += 1;
        }
        true
    }

    /// Whether this image runs `name` (`all` runs every variant that fits in the SRAM, and
    /// not nalgebra's SVD, which crashes the simulator).
    const fn runs(name: &str) -> bool {
        same(VARIANT, name)
            || (same(VARIANT, "all")
                && !same(name, "crc8-table16")
                && !same(name, "crc32-table16")
                && !same(name, "eig-nalgebra12")
                && !same(name, "eig-svd8")
                && !same(name, "eig-svd12"))
    }

    // ------------------------------------------------------------------ UART, marker

    /// USART0, polled (no interrupt, no queue: the queue is one of the things measured).
    struct Tx;

    impl Tx {
        fn bytes(bytes: &[u8]) {
            // SAFETY: USART0 is used by this writer alone.
            let u = unsafe { &*pac::USART0::ptr() };
            for &b in bytes {
                while u.ucsr0a().read().bits() & (1 << 5) == 0 {}
                u.udr0().write(|w| unsafe { w.bits(b) });
            }
        }
    }

    impl uWrite for Tx {
        type Error = core::convert::Infallible;
        fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
            Tx::bytes(s.as_bytes());
            Ok(())
        }
    }

    /// Data-space addresses of PORTB and DDRB (ATmega2560 datasheet, register summary).
    const PORTB: *mut u8 = 0x25 as *mut u8;
    const DDRB: *mut u8 = 0x24 as *mut u8;
    /// PB7, the marker pin.
    const MARK: u8 = 1 << 7;

    /// Measurement `label` of `variant`: its line, then the marker around `f`. The caller completes
    /// the line with [`word`]s and [`end`].
    #[inline(always)]
    fn measure<R>(variant: &str, label: &str, f: impl FnOnce() -> R) -> R {
        uwrite!(Tx, "M {} {}", variant, label).ok();
        compiler_fence(Ordering::SeqCst);
        // SAFETY: PORTB is an I/O register owned by this image.
        unsafe { write_volatile(PORTB, MARK) };
        compiler_fence(Ordering::SeqCst);
        let r = black_box(f());
        compiler_fence(Ordering::SeqCst);
        // SAFETY: as above.
        unsafe { write_volatile(PORTB, 0) };
        compiler_fence(Ordering::SeqCst);
        r
    }

    fn word(w: impl ufmt::uDisplay) {
        uwrite!(Tx, " {}", w).ok();
    }

    fn end() {
        Tx.write_str("\n").ok();
    }

    // ------------------------------------------------------------------ empty

    #[inline(never)]
    fn nothing() {
        black_box(());
    }

    // ------------------------------------------------------------------ Cholesky

    const N_MAX: usize = 13;
    const PACKED: usize = N_MAX * (N_MAX + 1) / 2;

    /// `A = M Mᵀ` packed (row `i`, column `j ≤ i` at `i (i + 1) / 2 + j`) with `M` lower
    /// triangular, 4 on the diagonal and `((5 i + 3 j) mod 3) − 1` below it: small integers,
    /// so `A` is exact in `f32` and the host rebuilds the same system in `f64`. Its leading
    /// `n × n` block is the `n × n` problem. The right-hand side is `b_i = i − 6`.
    fn problem() -> ([f32; PACKED], [f32; N_MAX]) {
        let m = |i: usize, j: usize| -> i32 {
            if j == i {
                4
            } else if j < i {
                ((5 * i + 3 * j) % 3) as i32 - 1
            } else {
                0
            }
        };
        let mut a = [0.0f32; PACKED];
        for i in 0..N_MAX {
            for j in 0..=i {
                let s: i32 = (0..=j).map(|k| m(i, k) * m(j, k)).sum();
                a[i * (i + 1) / 2 + j] = s as f32;
            }
        }
        let mut b = [0.0f32; N_MAX];
        for (i, v) in b.iter_mut().enumerate() {
            *v = i as f32 - 6.0;
        }
        (a, b)
    }

    /// Factor + solve with the packed Cholesky as `ridge_core::Factor` uses it (copy the
    /// leading block into the factor's storage, factor in place, forward and back substitution).
    #[inline(never)]
    fn chol_ours(src: &[f32; PACKED], n: usize, x: &mut [f32; N_MAX]) -> bool {
        use crate::cholesky::{backward, factor_in_place, forward, packed_len};
        let mut l = [0.0f32; PACKED];
        let len = packed_len(n);
        l[..len].copy_from_slice(&src[..len]);
        let tol = 4.0 * N_MAX as f32 * f32::EPSILON;
        if factor_in_place(&mut l, n, 0, n, tol).is_err() {
            return false;
        }
        forward(&l, n, x);
        backward(&l, n, x);
        true
    }

    fn print_solution(ok: bool, x: &[f32], n: usize) {
        word(u8::from(ok));
        for v in &x[..n] {
            word(v.to_bits());
        }
        end();
    }

    /// The square root the factorisation takes (once per pivot): `Real::sqrt` for `f32`.
    #[inline(never)]
    fn sqrt_ours(x: f32) -> f32 {
        <f32 as ridge_core::Real>::sqrt(x)
    }

    fn bench_sqrt(variant: &str, sqrt: impl Fn(f32) -> f32) {
        let r = measure(variant, "sqrt", || sqrt(black_box(2.0)));
        word(r.to_bits());
        end();
    }

    fn bench_chol_ours() {
        let (a, b) = problem();
        for n in [12usize, 13] {
            let mut x = b;
            let label = if n == 12 { "chol12" } else { "chol13" };
            let ok = measure("chol-ours", label, || chol_ours(&a, black_box(n), &mut x));
            print_solution(ok, &x, n);
        }
    }

    /// Factor + solve with nalgebra: the full matrix from the same packed source,
    /// `Cholesky::new`, `solve_mut`.
    #[cfg(feature = "bench-crates")]
    #[inline(never)]
    fn chol_nalgebra<const N: usize>(src: &[f32; PACKED], x: &mut [f32; N_MAX]) -> bool {
        use nalgebra::{SMatrix, SVector};
        let a = SMatrix::<f32, N, N>::from_fn(|i, j| {
            let (r, c) = if i >= j { (i, j) } else { (j, i) };
            src[r * (r + 1) / 2 + c]
        });
        let Some(ch) = a.cholesky() else {
            return false;
        };
        let mut b = SVector::<f32, N>::from_fn(|i, _| x[i]);
        ch.solve_mut(&mut b);
        for (xi, bi) in x.iter_mut().zip(b.iter()) {
            *xi = *bi;
        }
        true
    }

    /// nalgebra's square root for `f32` (`ComplexField::sqrt`, simba with `libm`).
    #[cfg(feature = "bench-crates")]
    #[inline(never)]
    fn sqrt_nalgebra(x: f32) -> f32 {
        <f32 as nalgebra::ComplexField>::sqrt(x)
    }

    #[cfg(feature = "bench-crates")]
    fn bench_chol_nalgebra<const N: usize>(variant: &str, label: &str) {
        let (a, b) = problem();
        let mut x = b;
        let ok = measure(variant, label, || chol_nalgebra::<N>(&a, &mut x));
        print_solution(ok, &x, N);
    }

    // ------------------------------------------------------------------ eigen-decomposition

    /// Columns of the eigen-decomposition problems.
    const EIG_MAX: usize = 12;

    /// `M`, lower triangular: the Cholesky factor of the Toeplitz matrix `ρ^|i−j|` with
    /// `ρ = 0.99` (`M_i0 = ρ^i`, `M_ij = ρ^(i−j) √(1 − ρ²)`), a Gram of strongly correlated lags
    /// like the pump's (its eigenvalues span 0.005 to 12 for 12 columns), in `f32` by repeated
    /// products (the host forms the same values). Row-major, `EIG_MAX` wide.
    fn eig_problem() -> [[f32; EIG_MAX]; EIG_MAX] {
        let rho = 0.99f32;
        let s = <f32 as ridge_core::Real>::sqrt(1.0 - rho * rho);
        let mut m = [[0.0f32; EIG_MAX]; EIG_MAX];
        let mut pow = [1.0f32; EIG_MAX];
        for k in 1..EIG_MAX {
            pow[k] = pow[k - 1] * rho;
        }
        for i in 0..EIG_MAX {
            m[i][0] = pow[i];
            for j in 1..=i {
                m[i][j] = pow[i - j] * s;
            }
        }
        m
    }

    /// The leading `n × n` block of `M` into the decomposition's column storage, rotated until
    /// orthogonal; the eigenvalues of `M Mᵀ` are the squared column norms (`ridge_core::modal`
    /// then reads everything else from the columns).
    #[inline(never)]
    fn eig_ours(m: &[[f32; EIG_MAX]; EIG_MAX], n: usize, out: &mut [f32; EIG_MAX]) -> bool {
        use crate::eigen::{slot, Columns, COLS_MAX, STORAGE, TAIL};
        let (mut head, mut second) = ([0.0f32; STORAGE], [0.0f32; STORAGE]);
        for j in 0..n {
            let (first, at) = slot(j);
            let dst = if first { &mut head } else { &mut second };
            for i in 0..n {
                dst[at + i] = m[i][j];
            }
        }
        let Some((tail, _)) = second.split_first_chunk_mut::<TAIL>() else {
            return false;
        };
        let Ok(mut cols) = Columns::new(&mut head, tail, n) else {
            return false;
        };
        if cols
            .orthogonalise(&mut [0.0; COLS_MAX], &mut || {})
            .is_err()
        {
            return false;
        }
        for (j, v) in out.iter_mut().enumerate().take(n) {
            *v = cols.norm2(j);
        }
        true
    }

    fn print_eigenvalues(ok: bool, e: &[f32]) {
        word(u8::from(ok));
        for v in e {
            word(v.to_bits());
        }
        end();
    }

    fn bench_eig_ours() {
        let m = eig_problem();
        for n in [8usize, 12] {
            let mut e = [0.0f32; EIG_MAX];
            let label = if n == 8 { "eig8" } else { "eig12" };
            let ok = measure("eig-ours", label, || eig_ours(&m, black_box(n), &mut e));
            print_eigenvalues(ok, &e[..n]);
        }
    }

    /// `eig_nalgebra{8,12}`: `nalgebra::SymmetricEigen` of `B = M Mᵀ` formed in `f32`
    /// (eigenvalues and vectors); `eig_svd{8,12}`: `nalgebra::SVD` of `M` with its left
    /// singular vectors (`M Mᵀ = U Σ² Uᵀ`). One function per size (nalgebra's sizes are types).
    #[cfg(feature = "bench-crates")]
    macro_rules! eig_nalgebra {
        ($eig:ident, $svd:ident, $n:literal) => {
            #[inline(never)]
            fn $eig(m: &[[f32; EIG_MAX]; EIG_MAX], out: &mut [f32; EIG_MAX]) {
                let mm = nalgebra::SMatrix::<f32, $n, $n>::from_fn(|i, j| m[i][j]);
                let eig = nalgebra::SymmetricEigen::new(mm * mm.transpose());
                for (o, v) in out.iter_mut().zip(eig.eigenvalues.iter()) {
                    *o = *v;
                }
                black_box(&eig.eigenvectors);
            }

            #[inline(never)]
            fn $svd(m: &[[f32; EIG_MAX]; EIG_MAX], out: &mut [f32; EIG_MAX]) {
                let mm = nalgebra::SMatrix::<f32, $n, $n>::from_fn(|i, j| m[i][j]);
                let svd = nalgebra::SVD::new(mm, true, false);
                for (o, v) in out.iter_mut().zip(svd.singular_values.iter()) {
                    *o = *v * *v;
                }
                black_box(&svd.u);
            }
        };
    }
    #[cfg(feature = "bench-crates")]
    eig_nalgebra!(eig_nalgebra8, eig_svd8, 8);
    #[cfg(feature = "bench-crates")]
    eig_nalgebra!(eig_nalgebra12, eig_svd12, 12);

    #[cfg(feature = "bench-crates")]
    fn bench_eig_crate<const N: usize>(
        variant: &str,
        f: fn(&[[f32; EIG_MAX]; EIG_MAX], &mut [f32; EIG_MAX]),
    ) {
        let m = eig_problem();
        let mut e = [0.0f32; EIG_MAX];
        let label = if N == 8 { "eig8" } else { "eig12" };
        measure(variant, label, || f(&m, &mut e));
        print_eigenvalues(true, &e[..N]);
    }

    // ------------------------------------------------------------------ ring buffers

    /// Push one byte, pop one byte (each timed alone: in the firmware they run in different
    /// contexts), then 255 pushes and 255 pops in one loop.
    macro_rules! ring_bench {
        ($variant:expr, $push:expr, $pop:expr) => {{
            use core::hint::black_box;
            use $crate::image::{end, measure, word};
            // Non-empty, non-full state first, as in use.
            for i in 0..10u8 {
                $push(i);
            }
            let ok = measure($variant, "push", || $push(black_box(0x5A)));
            word(u8::from(ok));
            end();
            let got = measure($variant, "pop", || $pop());
            word(u16::from(got.unwrap_or(0xFF)));
            end();
            while $pop().is_some() {}
            let (pushed, sum) = measure($variant, "burst255", || {
                let mut pushed = 0u16;
                for i in 0..255u8 {
                    pushed += u16::from($push(black_box(i)));
                }
                let mut sum = 0u16;
                while let Some(v) = $pop() {
                    sum += u16::from(v);
                }
                (pushed, sum)
            });
            word(pushed);
            word(sum);
            end();
        }};
    }

    static RING: ridge_pump_firmware::ring::Ring<256> = ridge_pump_firmware::ring::Ring::new();

    #[inline(never)]
    fn push_ours(b: u8) -> bool {
        RING.push(b)
    }

    #[inline(never)]
    fn pop_ours() -> Option<u8> {
        RING.pop()
    }

    fn bench_ring_ours() {
        ring_bench!("ring-ours", push_ours, pop_ours);
    }

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    static mut Q08: heapless::spsc::Queue<u8, 256> = heapless::spsc::Queue::new();
    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    static mut C08: Option<heapless::spsc::Consumer<'static, u8, 256>> = None;

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    #[inline(never)]
    fn push_heapless08(p: &mut heapless::spsc::Producer<'static, u8, 256>, b: u8) -> bool {
        p.enqueue(b).is_ok()
    }

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    #[inline(never)]
    fn pop_heapless08() -> Option<u8> {
        // SAFETY: single-threaded image; `C08` is set once before use.
        let c = unsafe { (*core::ptr::addr_of_mut!(C08)).as_mut() };
        c.and_then(|c| c.dequeue())
    }

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    fn bench_heapless08() {
        // The producer stays with the writer (here), the consumer goes to a static for the
        // interrupt handler, as heapless's docs split a `&'static mut Queue`.
        // SAFETY: `Q08` is split once, here, before any use of `C08`.
        let mut p = unsafe {
            let (p, c) = (*core::ptr::addr_of_mut!(Q08)).split();
            *core::ptr::addr_of_mut!(C08) = Some(c);
            p
        };
        ring_bench!(
            "ring-heapless08",
            |b| push_heapless08(&mut p, b),
            pop_heapless08
        );
    }

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    static mut Q09: heapless09::spsc::Queue<u8, 256> = heapless09::spsc::Queue::new();
    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    static mut C09: Option<heapless09::spsc::Consumer<'static, u8>> = None;

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    #[inline(never)]
    fn push_heapless09(p: &mut heapless09::spsc::Producer<'static, u8>, b: u8) -> bool {
        p.enqueue(b).is_ok()
    }

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    #[inline(never)]
    fn pop_heapless09() -> Option<u8> {
        // SAFETY: single-threaded image; `C09` is set once before use.
        let c = unsafe { (*core::ptr::addr_of_mut!(C09)).as_mut() };
        c.and_then(|c| c.dequeue())
    }

    #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
    fn bench_heapless09() {
        // The producer stays with the writer (here), the consumer goes to a static for the
        // interrupt handler, as heapless's docs split a `&'static mut Queue`.
        // SAFETY: `Q09` is split once, here, before any use of `C09`.
        let mut p = unsafe {
            let (p, c) = (*core::ptr::addr_of_mut!(Q09)).split();
            *core::ptr::addr_of_mut!(C09) = Some(c);
            p
        };
        ring_bench!(
            "ring-heapless09",
            |b| push_heapless09(&mut p, b),
            pop_heapless09
        );
    }

    // ------------------------------------------------------------------ CRC

    /// The SFM3300's CRC-8: polynomial 0x31, initial value 0x00, no reflection, no final XOR
    /// (check value of "123456789": 0xA2).
    #[cfg(feature = "bench-crates")]
    static SFM_CRC8: crc::Algorithm<u8> = crc::Algorithm {
        width: 8,
        poly: 0x31,
        init: 0x00,
        refin: false,
        refout: false,
        xorout: 0x00,
        check: 0xA2,
        residue: 0x00,
    };

    /// One SFM3300 frame (1.000 slm and its CRC), and the datasheet's two vectors.
    const FRAME: [u8; 3] = [0x80, 0x78, 0x62];

    fn bench_crc8(variant: &str, crc8: impl Fn(&[u8]) -> u8) {
        let frame = FRAME;
        let ok = measure(variant, "frame", || {
            let f = black_box(&frame);
            crc8(&f[..2]) == f[2]
        });
        word(u8::from(ok));
        word(crc8(black_box(&[0xBE, 0xEF])));
        word(crc8(black_box(&[0x80, 0x00])));
        word(crc8(black_box(b"123456789")));
        end();
    }

    #[inline(never)]
    fn crc8_ours(d: &[u8]) -> u8 {
        ridge_pump_firmware::sfm3300::crc8(d)
    }

    #[cfg(feature = "bench-crates")]
    mod crc_crate {
        use crc::{Crc, NoTable, Table, CRC_32_ISO_HDLC};

        pub static CRC8_NOTABLE: Crc<u8, NoTable> = Crc::<u8, NoTable>::new(&super::SFM_CRC8);
        pub static CRC8_TABLE1: Crc<u8, Table<1>> = Crc::<u8, Table<1>>::new(&super::SFM_CRC8);
        pub static CRC8_TABLE16: Crc<u8, Table<16>> = Crc::<u8, Table<16>>::new(&super::SFM_CRC8);
        pub static CRC32_NOTABLE: Crc<u32, NoTable> = Crc::<u32, NoTable>::new(&CRC_32_ISO_HDLC);
        pub static CRC32_TABLE1: Crc<u32, Table<1>> = Crc::<u32, Table<1>>::new(&CRC_32_ISO_HDLC);
        pub static CRC32_TABLE16: Crc<u32, Table<16>> =
            Crc::<u32, Table<16>>::new(&CRC_32_ISO_HDLC);

        #[inline(never)]
        pub fn crc8_notable(d: &[u8]) -> u8 {
            CRC8_NOTABLE.checksum(d)
        }
        #[inline(never)]
        pub fn crc8_table1(d: &[u8]) -> u8 {
            CRC8_TABLE1.checksum(d)
        }
        #[inline(never)]
        pub fn crc8_table16(d: &[u8]) -> u8 {
            CRC8_TABLE16.checksum(d)
        }
        #[inline(never)]
        pub fn crc32_notable(d: &[u8]) -> u32 {
            CRC32_NOTABLE.checksum(d)
        }
        #[inline(never)]
        pub fn crc32_table1(d: &[u8]) -> u32 {
            CRC32_TABLE1.checksum(d)
        }
        #[inline(never)]
        pub fn crc32_table16(d: &[u8]) -> u32 {
            CRC32_TABLE16.checksum(d)
        }
    }

    /// The 65 bytes a persisted record's CRC covers (a fixed pattern).
    fn record() -> [u8; 65] {
        let mut r = [0u8; 65];
        for (i, b) in r.iter_mut().enumerate() {
            *b = (i as u8).wrapping_mul(37).wrapping_add(11);
        }
        r
    }

    fn bench_crc32(variant: &str, crc32: impl Fn(&[u8]) -> u32) {
        let rec = record();
        let c = measure(variant, "record", || crc32(black_box(&rec)));
        word(c);
        word(crc32(black_box(b"123456789")));
        end();
    }

    #[inline(never)]
    fn crc32_ours(d: &[u8]) -> u32 {
        ridge_pump_firmware::persist::crc32(d)
    }

    // ------------------------------------------------------------------ float formatting

    /// A line buffer for the formatted number.
    struct Buf {
        bytes: [u8; 40],
        len: usize,
    }

    impl Buf {
        const fn new() -> Self {
            Buf {
                bytes: [0; 40],
                len: 0,
            }
        }
        /// Prints the buffer as one word (raw bytes: no UTF-8 check, whose 256-byte table would
        /// count against the routine).
        fn print(&self) {
            Tx.write_str(" ").ok();
            Tx::bytes(&self.bytes[..self.len]);
        }
        fn push(&mut self, s: &str) {
            for &b in s.as_bytes() {
                if let Some(slot) = self.bytes.get_mut(self.len) {
                    *slot = b;
                    self.len += 1;
                }
            }
        }
    }

    impl uWrite for Buf {
        type Error = core::convert::Infallible;
        fn write_str(&mut self, s: &str) -> Result<(), Self::Error> {
            self.push(s);
            Ok(())
        }
    }

    impl core::fmt::Write for Buf {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            self.push(s);
            Ok(())
        }
    }

    /// Values printed with 4 decimals (labels `f0`…).
    const VALUES: [f32; 6] = [-1.9472, 273.0671, -0.5, 0.00049, 1.00005, -12345.678];
    const LABELS: [&str; 6] = ["f0", "f1", "f2", "f3", "f4", "f5"];

    fn bench_fmt(variant: &str, format: impl Fn(f32, &mut Buf)) {
        for (v, label) in VALUES.iter().zip(LABELS) {
            let mut buf = Buf::new();
            measure(variant, label, || format(black_box(*v), &mut buf));
            buf.print();
            end();
        }
    }

    #[inline(never)]
    fn fmt_ours(v: f32, buf: &mut Buf) {
        uwrite!(buf, "{}", ridge_pump_firmware::numfmt::Fixed::new(v, 4)).ok();
    }

    #[cfg(feature = "bench-crates")]
    #[inline(never)]
    fn fmt_ufmt_float(v: f32, buf: &mut Buf) {
        uwrite!(buf, "{}", ufmt_float::uFmt_f32::Four(v)).ok();
    }

    #[inline(never)]
    fn fmt_core(v: f32, buf: &mut Buf) {
        core::fmt::Write::write_fmt(buf, format_args!("{v:.4}")).ok();
    }

    // ------------------------------------------------------------------ re-identification

    type Win<'a> = ridge_core::reid::Window<'a>;
    type Refit = ridge_core::reid::Refit<f32>;

    /// One tick's statistics: a rank-1 update of the 10-column window.
    #[inline(never)]
    fn reid_push(w: &mut Win<'_>, u: i16, y: i16) -> bool {
        w.push(u, y).is_ok()
    }

    /// The breath boundary's forgetting.
    #[inline(never)]
    fn reid_breath(w: &mut Win<'_>) {
        w.end_breath();
    }

    /// The snapshot that starts a re-estimate.
    #[inline(never)]
    fn reid_start(w: &Win<'_>) -> Option<Refit> {
        let m = ridge_core::RidgeM {
            max_iter: 3,
            tol: 0.0,
            ..ridge_core::RidgeM::PAPER
        };
        Refit::start(w, m, &ridge_pump_firmware::units::SCALE).ok()
    }

    /// The snapshot's set-up when it is taken in parts (the firmware's): the checks, nothing
    /// converted.
    #[inline(never)]
    fn reid_begin(w: &Win<'_>) -> Option<Refit> {
        let m = ridge_core::RidgeM {
            max_iter: 3,
            tol: 0.0,
            ..ridge_core::RidgeM::PAPER
        };
        Refit::begin(w, m).ok()
    }

    /// The snapshot's first part: the statistics converted.
    #[inline(never)]
    fn reid_rows(r: &mut Refit, w: &Win<'_>) -> bool {
        r.take_rows(w, &ridge_pump_firmware::units::SCALE).is_ok()
    }

    /// The snapshot's second part: the output's and input's RMS.
    #[inline(never)]
    fn reid_responses(r: &mut Refit, w: &Win<'_>) -> bool {
        r.take_responses(w, &ridge_pump_firmware::units::SCALE)
            .is_ok()
    }

    /// One unit of the re-estimate: 0 working, 1 done, 2 refused.
    #[inline(never)]
    fn reid_unit(r: &mut Refit) -> u8 {
        match r.step(1) {
            ridge_core::reid::RefitStep::Working => 0,
            ridge_core::reid::RefitStep::Done(..) => 1,
            ridge_core::reid::RefitStep::Refused(_) => 2,
        }
    }

    fn bench_reid_ours() {
        use firmware_diag::arith_check::{reid_fill, REID_STRUCTURE};
        use ridge_core::reid::{window_len, Window};
        let mut store = [0i64; window_len(9)];
        let Ok(mut w) = Window::new(REID_STRUCTURE, ridge_core::Offset::Intercept, 2, &mut store)
        else {
            Tx.write_str("reid window error\n").ok();
            return;
        };
        reid_fill(&mut w, 1499);
        let ok = measure("reid-ours", "push", || {
            reid_push(&mut w, black_box(-700), black_box(950))
        });
        word(u8::from(ok));
        end();
        measure("reid-ours", "breath", || reid_breath(&mut w));
        word(w.weight());
        end();
        let Some(mut r) = measure("reid-ours", "start", || reid_start(&w)) else {
            Tx.write_str("reid start error\n").ok();
            return;
        };
        end();
        // The same snapshot in the firmware's parts.
        if let Some(mut p) = measure("reid-ours", "begin", || reid_begin(&w)) {
            end();
            let ok = measure("reid-ours", "rows", || reid_rows(&mut p, &w));
            word(u8::from(ok));
            end();
            let ok = measure("reid-ours", "responses", || reid_responses(&mut p, &w));
            word(u8::from(ok));
            end();
        }
        // 10 factor rows, the solution, 3 iterates.
        let labels = [
            "row0", "row1", "row2", "row3", "row4", "row5", "row6", "row7", "row8", "row9",
            "solution", "iter1", "iter2", "iter3",
        ];
        for label in labels {
            let s = measure("reid-ours", label, || reid_unit(&mut r));
            word(s);
            end();
        }
    }

    // ------------------------------------------------------------------ main

    #[avr_device::entry]
    fn main() -> ! {
        // SAFETY: the image owns every peripheral; nothing else runs.
        let dp = unsafe { pac::Peripherals::steal() };
        // 115 200 baud with U2X at 16 MHz (UBRR 16), 8N1, transmitter only.
        dp.USART0.ubrr0().write(|w| unsafe { w.bits(16) });
        dp.USART0.ucsr0a().write(|w| unsafe { w.bits(1 << 1) });
        dp.USART0.ucsr0b().write(|w| unsafe { w.bits(1 << 3) });
        dp.USART0.ucsr0c().write(|w| unsafe { w.bits(0b110) });
        // SAFETY: PB7 as output, low.
        unsafe {
            write_volatile(DDRB, MARK);
            write_volatile(PORTB, 0);
        }
        uwrite!(Tx, "BENCH {}\n", VARIANT).ok();

        // Every image: the bare call (the calibration of `empty`), so that what all images
        // share is in `empty` too.
        {
            measure("empty", "call", nothing);
            // Every integer width the other images print, so that their printing is in here.
            word(black_box(1u8));
            word(black_box(2u16));
            word(black_box(3u32));
            word(black_box("x"));
            end();
        }
        if const { runs("sqrt-ours") } {
            bench_sqrt("sqrt-ours", sqrt_ours);
        }
        if const { runs("chol-ours") } {
            bench_chol_ours();
        }
        #[cfg(feature = "bench-crates")]
        {
            if const { runs("sqrt-nalgebra") } {
                bench_sqrt("sqrt-nalgebra", sqrt_nalgebra);
            }
            if const { runs("chol-nalgebra12") } {
                bench_chol_nalgebra::<12>("chol-nalgebra12", "chol12");
            }
            if const { runs("chol-nalgebra13") } {
                bench_chol_nalgebra::<13>("chol-nalgebra13", "chol13");
            }
        }
        if const { runs("eig-ours") } {
            bench_eig_ours();
        }
        #[cfg(feature = "bench-crates")]
        {
            if const { runs("eig-nalgebra8") } {
                bench_eig_crate::<8>("eig-nalgebra8", eig_nalgebra8);
            }
            if const { runs("eig-nalgebra12") } {
                bench_eig_crate::<12>("eig-nalgebra12", eig_nalgebra12);
            }
            if const { runs("eig-svd8") } {
                bench_eig_crate::<8>("eig-svd8", eig_svd8);
            }
            if const { runs("eig-svd12") } {
                bench_eig_crate::<12>("eig-svd12", eig_svd12);
            }
        }
        if const { runs("ring-ours") } {
            bench_ring_ours();
        }
        #[cfg(any(feature = "bench-crates", feature = "bench-heapless-core-atomics"))]
        {
            if const { runs("ring-heapless08") } {
                bench_heapless08();
            }
            if const { runs("ring-heapless09") } {
                bench_heapless09();
            }
        }
        if const { runs("crc8-ours") } {
            bench_crc8("crc8-ours", crc8_ours);
        }
        if const { runs("crc32-ours") } {
            bench_crc32("crc32-ours", crc32_ours);
        }
        #[cfg(feature = "bench-crates")]
        {
            use crc_crate::*;
            if const { runs("crc8-notable") } {
                bench_crc8("crc8-notable", crc8_notable);
            }
            if const { runs("crc8-table1") } {
                bench_crc8("crc8-table1", crc8_table1);
            }
            if const { runs("crc8-table16") } {
                bench_crc8("crc8-table16", crc8_table16);
            }
            if const { runs("crc32-notable") } {
                bench_crc32("crc32-notable", crc32_notable);
            }
            if const { runs("crc32-table1") } {
                bench_crc32("crc32-table1", crc32_table1);
            }
            if const { runs("crc32-table16") } {
                bench_crc32("crc32-table16", crc32_table16);
            }
        }
        if const { runs("fmt-ours") } {
            bench_fmt("fmt-ours", fmt_ours);
        }
        #[cfg(feature = "bench-crates")]
        if const { runs("fmt-ufmt-float") } {
            bench_fmt("fmt-ufmt-float", fmt_ufmt_float);
        }
        if const { runs("fmt-core") } {
            bench_fmt("fmt-core", fmt_core);
        }
        if const { runs("reid-ours") } {
            bench_reid_ours();
        }

        Tx.write_str("DONE\n").ok();
        // Wait for the last byte to leave the shift register (TXC0), then stop: simavr ends
        // the run on `sleep` with interrupts disabled.
        // SAFETY: USART0 is ours.
        let u = unsafe { &*pac::USART0::ptr() };
        while u.ucsr0a().read().bits() & (1 << 6) == 0 {}
        avr_device::interrupt::disable();
        loop {
            avr_device::asm::sleep();
        }
    }

    #[panic_handler]
    fn panic(_: &PanicInfo) -> ! {
        Tx.write_str("PANIC\n").ok();
        loop {}
    }
}
