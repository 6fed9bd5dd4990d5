//! A firmware image's section sizes, as each harness's ELF reader counts them (the flash and
//! static RAM the report prints).

/// Section sizes of an image, bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sizes {
    /// Code and constants in flash (the ELF reader says which sections).
    pub text: u32,
    /// `.data` (initialised RAM, its image stored in flash too).
    pub data: u32,
    /// `.bss` and the RAM sections that are not initialised (`.noinit`, `.uninit`).
    pub bss: u32,
}

impl Sizes {
    /// Flash used: text + data.
    pub fn flash(&self) -> u32 {
        self.text + self.data
    }

    /// Static RAM: data + bss.
    pub fn ram(&self) -> u32 {
        self.data + self.bss
    }
}
