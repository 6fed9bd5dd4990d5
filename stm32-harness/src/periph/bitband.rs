//! The peripheral bit-band alias (RM0383 §2.3.2, "Bit banding"): each word of
//! 0x4200_0000–0x43FF_FFFF maps one bit of the peripheral region 0x4000_0000–0x400F_FFFF:
//! `alias = 0x4200_0000 + byte_offset × 32 + bit_number × 4`. The HAL sets RCC enable and
//! reset bits through it.
//!
//! A write of the alias word sets (bit 0 of the value = 1) or clears the bit by a
//! read-modify-write of the peripheral word holding it; a read returns the bit. Simplification:
//! the read-modify-write reads the whole word with its side effects (as the bus matrix does on
//! the chip for the registers whose reads have none, which is all the HAL uses it on).

/// Start of the peripheral bit-band alias.
pub const ALIAS: u32 = 0x4200_0000;
/// Size of the alias region.
pub const ALIAS_SIZE: u32 = 0x0200_0000;
/// Start of the peripheral region it maps.
pub const REGION: u32 = 0x4000_0000;

/// The word address and bit (0..31) an alias address maps.
pub fn target(alias: u32) -> (u32, u32) {
    let off = alias - ALIAS;
    let byte = REGION + off / 32;
    let bit = (off % 32) / 4;
    (byte & !3, bit + 8 * (byte & 3))
}

/// Whether alias address `addr` maps a bit inside the 0x400-byte block at `base`.
pub fn target_in(addr: u32, base: u32) -> bool {
    (ALIAS..ALIAS + ALIAS_SIZE).contains(&addr) && (base..base + 0x400).contains(&target(addr).0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alias_maps_the_manuals_example() {
        // RM0383 §2.3.2 example, for SRAM: 0x2200_0000 + 0x300 × 32 + 2 × 4 = 0x2200_6008
        // maps bit 2 of 0x2000_0300; the peripheral alias is laid out the same way.
        assert_eq!(target(0x4200_6008), (0x4000_0300, 2));
        // RCC_APB1ENR (0x4002_3840) bit 3 (TIM5EN): 0x4200_0000 + 0x2_3840 × 32 + 3 × 4.
        assert_eq!(target(0x4247_080C), (0x4002_3840, 3));
        // A bit of the second byte of a word.
        assert_eq!(target(0x4200_0000 + 0x41 * 32 + 4), (0x4000_0040, 9));
    }
}
