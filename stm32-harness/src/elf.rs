//! The firmware ELF: its loadable segments (what `cargo flash-f411` writes to flash), its
//! symbols and its section sizes.
//!
//! A 32-bit little-endian ELF reader of the few fields needed (program headers, section
//! headers, `.symtab`), the way `simavr-harness` reads its image's sizes: the `object` crate
//! would do the same at the cost of a dependency tree the harness does not otherwise need.

use std::path::Path;

/// One `PT_LOAD` segment: its load (physical) address and the bytes stored in the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Segment {
    /// Load address (`p_paddr`): where a flasher writes it.
    pub addr: u32,
    /// Contents (`p_filesz` bytes).
    pub bytes: Vec<u8>,
}

/// A symbol from `.symtab`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Symbol {
    /// Name.
    pub name: String,
    /// Value (address; Thumb functions have bit 0 set).
    pub addr: u32,
    /// Size, bytes.
    pub size: u32,
}

/// Section sizes of an ARM ELF, bytes (as `arm-none-eabi-size -B` counts them: text = the
/// allocated read-only sections, `.vector_table`, `.text`, `.rodata`, …; bss = `.bss` and
/// `.uninit`).
pub use harness_kit::image::Sizes;

/// A loaded image.
#[derive(Clone, Debug, Default)]
pub struct Image {
    /// Loadable segments with file contents.
    pub segments: Vec<Segment>,
    /// Symbols.
    pub symbols: Vec<Symbol>,
    /// Section sizes.
    pub sizes: Sizes,
}

impl Image {
    /// The symbol named `name`.
    pub fn symbol(&self, name: &str) -> Option<&Symbol> {
        self.symbols.iter().find(|s| s.name == name)
    }
}

struct Reader<'a> {
    b: &'a [u8],
}

impl Reader<'_> {
    fn u16(&self, o: usize) -> Result<u16, String> {
        let s = self.b.get(o..o + 2).ok_or("truncated ELF")?;
        Ok(u16::from_le_bytes([s[0], s[1]]))
    }

    fn u32(&self, o: usize) -> Result<u32, String> {
        let s = self.b.get(o..o + 4).ok_or("truncated ELF")?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }

    fn bytes(&self, o: usize, n: usize) -> Result<&[u8], String> {
        self.b
            .get(o..o + n)
            .ok_or_else(|| "truncated ELF".to_string())
    }

    fn cstr(&self, o: usize) -> Result<String, String> {
        let s = self.b.get(o..).ok_or("truncated ELF")?;
        let end = s.iter().position(|&c| c == 0).unwrap_or(s.len());
        Ok(String::from_utf8_lossy(&s[..end]).into_owned())
    }
}

const PT_LOAD: u32 = 1;
const SHT_SYMTAB: u32 = 2;
const SHT_NOBITS: u32 = 8;
const SHF_WRITE: u32 = 1;
const SHF_ALLOC: u32 = 2;

/// Reads `path` (a 32-bit little-endian ARM ELF).
pub fn load(path: &Path) -> Result<Image, String> {
    let b = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse(&b).map_err(|e| format!("{}: {e}", path.display()))
}

/// Parses an ELF held in memory.
pub fn parse(b: &[u8]) -> Result<Image, String> {
    let r = Reader { b };
    if b.get(..6) != Some(b"\x7fELF\x01\x01") {
        return Err("not a 32-bit little-endian ELF".into());
    }
    if r.u16(0x12)? != 40 {
        return Err("not an ARM ELF".into());
    }
    let phoff = r.u32(0x1C)? as usize;
    let shoff = r.u32(0x20)? as usize;
    let phentsize = usize::from(r.u16(0x2A)?);
    let phnum = usize::from(r.u16(0x2C)?);
    let shentsize = usize::from(r.u16(0x2E)?);
    let shnum = usize::from(r.u16(0x30)?);
    let mut img = Image::default();
    for i in 0..phnum {
        let p = phoff + i * phentsize;
        if r.u32(p)? != PT_LOAD {
            continue;
        }
        let offset = r.u32(p + 4)? as usize;
        let paddr = r.u32(p + 12)?;
        let filesz = r.u32(p + 16)? as usize;
        if filesz > 0 {
            img.segments.push(Segment {
                addr: paddr,
                bytes: r.bytes(offset, filesz)?.to_vec(),
            });
        }
    }
    let sh = |i: usize| shoff + i * shentsize;
    for i in 0..shnum {
        let s = sh(i);
        let kind = r.u32(s + 4)?;
        let flags = r.u32(s + 8)?;
        let offset = r.u32(s + 0x10)? as usize;
        let size = r.u32(s + 0x14)?;
        let link = r.u32(s + 0x18)? as usize;
        if flags & SHF_ALLOC != 0 && size > 0 {
            if kind == SHT_NOBITS {
                img.sizes.bss += size;
            } else if flags & SHF_WRITE != 0 {
                img.sizes.data += size;
            } else {
                img.sizes.text += size;
            }
        }
        if kind == SHT_SYMTAB {
            let names = r.u32(sh(link) + 0x10)? as usize;
            for k in 0..size as usize / 16 {
                let e = offset + k * 16;
                let n = r.u32(e)? as usize;
                if n == 0 {
                    continue;
                }
                img.symbols.push(Symbol {
                    name: r.cstr(names + n)?,
                    addr: r.u32(e + 4)?,
                    size: r.u32(e + 8)?,
                });
            }
        }
    }
    Ok(img)
}
