//! Stack high-water mark.
//!
//! Right after the C runtime has set the stack pointer and initialised `.data`/`.bss`
//! (section `.init5`, before `main`), every byte from `__heap_start` (end of `.bss`/`.noinit`;
//! there is no heap) up to the stack pointer is filled with [`PAINT`]. [`usage`] later counts the
//! bytes from `__heap_start` upwards that still hold the paint: those were never touched by the
//! stack. (A stack byte that happens to be stored as `0xAA` at the deepest point would make the
//! figure one byte low: good enough for a budget.)

/// The paint byte.
pub const PAINT: u8 = 0xAA;

/// Last SRAM address of the ATmega2560 (RAMEND); the stack starts here.
pub const RAMEND: u16 = 0x21FF;

// .init5 runs after .init2 (SP = RAMEND) and .init4 (__do_copy_data, __do_clear_bss), falling
// through to .init6..9 and main. Z walks from __heap_start up to SP (X); r24 holds the paint.
// No call/ret: code in .initN sections must fall through.
core::arch::global_asm!(
    r#"
    .section .init5,"ax",@progbits
    ldi r30, lo8(__heap_start)
    ldi r31, hi8(__heap_start)
    in r26, 0x3d
    in r27, 0x3e
    ldi r24, 0xAA
1:
    cp r30, r26
    cpc r31, r27
    brsh 2f
    st Z+, r24
    rjmp 1b
2:
    "#
);

extern "C" {
    static __heap_start: u8;
}

/// `(used, free)`: bytes of stack used at the deepest point so far, and bytes never touched
/// between the end of static RAM and that point.
pub fn usage() -> (u16, u16) {
    let start = core::ptr::addr_of!(__heap_start) as u16;
    let mut free = 0u16;
    let mut address = start;
    while address <= RAMEND {
        // SAFETY: addresses between the end of .bss and RAMEND are SRAM; bytes not yet used by
        // the stack are read-only here, and volatile reads of live stack bytes are harmless.
        let byte = unsafe { core::ptr::read_volatile(address as *const u8) };
        if byte != PAINT {
            break;
        }
        free += 1;
        address += 1;
    }
    let total = RAMEND + 1 - start;
    (total - free, free)
}
