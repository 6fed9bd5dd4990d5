//! Worst-case stack of an AVR image by static analysis of its disassembly (`avr-objdump -d`),
//! as a bound that does not depend on which paths a simulation happened to take (the SRAM
//! paint of the `STACK` line only sees those).
//!
//! - **Own frame** of a function: the return address its caller pushed
//!   ([`RETURN_ADDRESS`] bytes on cores with more than 128 KB of flash), one byte per `push`
//!   and three per `rcall .+0` in its prologue (the first [`PROLOGUE`] instructions), and the
//!   frame it reserves by lowering the stack pointer it copied into Y (`in r28, 0x3d`,
//!   `in r29, 0x3e`, then `subi r28, lo` / `sbci r29, hi`, or `sbiw r28, k`). LLVM's AVR
//!   backend passes stack arguments through that frame, not with `push` in the body;
//!   [`analyze`] reports any `push` past the prologue, which would break this.
//! - **Call graph**: `call` / `rcall` to a label, and `jmp` / `rjmp` into another function
//!   (counted as calls: conservative, but a cycle through a jump is not recursion). A target
//!   `f+0x12` belongs to `f`.
//! - **Worst case** = the deepest path from `main` plus the deepest path of any interrupt
//!   vector (`__vector_N`; AVR handlers run with interrupts disabled and do not nest).
//!
//! Not handled, and reported when present: indirect calls (`icall`, `eicall`, `ijmp`,
//! `eijmp`), recursion.
//!
//! **Stack arguments** ([`StackAnalysis::stack_arguments`]): a function that reads or writes
//! `Y+q` above its own frame (pushes and reserved bytes), with Y the stack pointer its prologue
//! copied, uses arguments its caller passed on the stack. The rustc nightly used here
//! addresses them one byte too low on the ATmega2560: it allows two bytes for the return
//! address where the 22-bit program counter pushes three. Measured: `Wide::mul_sub(&i64 ×
//! 4)`, whose references the compiler turned into four `i64` values (32 bytes, more than the
//! 18 argument registers r8–r25 hold), read its last two values one byte off and computed
//! wrong differences (`scripts/avr-arith-check`); the integer Gram's `is_constant(u32, i64,
//! i64)` read its last argument the same way on main until 2026-11-24. Covered: slots
//! `Y+1 … Y+63` reached without moving Y; a frame so large that its arguments are only
//! reachable after moving Y is not checked.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// Return address bytes pushed by `call` on the ATmega2560 (22-bit program counter).
pub const RETURN_ADDRESS: u32 = 3;
/// Instructions of a function searched for its prologue.
pub const PROLOGUE: usize = 40;

/// One function of the image.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Function {
    /// Stack bytes of its own frame, return address included.
    pub own: u32,
    /// Functions it calls.
    pub callees: BTreeSet<String>,
    /// Functions it jumps into (`jmp`/`rjmp` to another symbol: shared tails such as
    /// avr-libc's float routines); counted like calls, but a cycle through a jump is not
    /// recursion (no return address is pushed).
    pub jumps: BTreeSet<String>,
    /// `push` instructions found after the prologue.
    pub late_pushes: u32,
    /// Indirect calls or jumps.
    pub indirect: u32,
    /// Whether the prologue copied the stack pointer into Y (a frame pointer).
    pub frame_pointer: bool,
    /// Bytes between Y and the return address: pushes plus the reserved frame.
    pub below_return: u32,
    /// The highest `Y+q` a `ldd`/`std` uses (0 for none).
    pub highest_slot: u32,
}

impl Function {
    /// Whether it reads or writes above its own frame through the frame pointer: arguments
    /// its caller passed on the stack (see the module docs).
    pub fn uses_stack_arguments(&self) -> bool {
        self.frame_pointer && self.highest_slot > self.below_return
    }
}

/// A deepest call path: total bytes and `(function, own frame)` from the root down.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CallPath {
    /// Stack bytes of the whole path.
    pub bytes: u32,
    /// The functions on it, root first, with their own frames.
    pub frames: Vec<(String, u32)>,
}

/// The stack analysis of one image: deepest paths (bytes) and what could make the bound
/// incomplete.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StackAnalysis {
    /// Deepest path from `main`.
    pub main: CallPath,
    /// Deepest path of any interrupt handler.
    pub interrupt: CallPath,
    /// Functions on a call cycle (their depth is not bounded by the analysis).
    pub recursive: BTreeSet<String>,
    /// Functions with indirect calls or jumps (callees unknown).
    pub indirect: BTreeSet<String>,
    /// Functions with a `push` after the prologue (frame possibly underestimated).
    pub late_pushes: BTreeSet<String>,
    /// Functions that use arguments passed on the stack (miscompiled on the ATmega2560, see
    /// the module docs).
    pub stack_arguments: BTreeSet<String>,
}

impl StackAnalysis {
    /// The worst-case stack: main path plus the deepest interrupt handler.
    pub fn worst(&self) -> u32 {
        self.main.bytes + self.interrupt.bytes
    }

    /// `true` when the bound is complete (no recursion, no indirect calls, no late pushes).
    pub fn complete(&self) -> bool {
        self.recursive.is_empty() && self.indirect.is_empty() && self.late_pushes.is_empty()
    }
}

/// Parses `avr-objdump -d` output into functions.
pub fn parse(disassembly: &str) -> BTreeMap<String, Function> {
    let mut funcs: BTreeMap<String, Function> = BTreeMap::new();
    let mut current: Option<String> = None;
    let mut index = 0usize;
    // The frame is what the prologue subtracts from the stack pointer it just copied into Y
    // (`in r28, 0x3d` / `in r29, 0x3e`); later `subi r28` / `sbiw r28` only move Y to reach
    // far slots and are not counted.
    let mut sp_in_y = false;
    for line in disassembly.lines() {
        if let Some(name) = label(line) {
            let f = funcs.entry(name.to_string()).or_default();
            f.own = RETURN_ADDRESS;
            current = Some(name.to_string());
            index = 0;
            sp_in_y = false;
            continue;
        }
        let (Some(name), Some((mnemonic, operands))) = (&current, instruction(line)) else {
            continue;
        };
        let Some(f) = funcs.get_mut(name) else {
            continue;
        };
        index += 1;
        let in_prologue = index <= PROLOGUE;
        match mnemonic {
            "push" if in_prologue => {
                f.own += 1;
                f.below_return += 1;
            }
            "push" => f.late_pushes += 1,
            "rcall" if operands.starts_with(".+0") && in_prologue => f.own += RETURN_ADDRESS,
            "in" if in_prologue && operands.starts_with("r29, 0x3e") => {
                sp_in_y = true;
                f.frame_pointer = true;
            }
            "subi" if sp_in_y && operands.starts_with("r28,") => {
                f.own += immediate(operands);
                f.below_return += immediate(operands);
            }
            "sbci" if sp_in_y && operands.starts_with("r29,") => {
                f.own += 256 * immediate(operands);
                f.below_return += 256 * immediate(operands);
                sp_in_y = false;
            }
            "sbiw" if sp_in_y && operands.starts_with("r28,") => {
                f.own += immediate(operands);
                f.below_return += immediate(operands);
                sp_in_y = false;
            }
            "ldd" | "std" => {
                if let Some(q) = y_slot(operands) {
                    f.highest_slot = f.highest_slot.max(q);
                }
            }
            "icall" | "eicall" | "ijmp" | "eijmp" => f.indirect += 1,
            _ => {}
        }
        if matches!(mnemonic, "call" | "rcall" | "jmp" | "rjmp") {
            if let Some(target) = target(line) {
                if target != name.as_str() && !target.is_empty() {
                    if mnemonic.ends_with("jmp") {
                        f.jumps.insert(target.to_string());
                    } else {
                        f.callees.insert(target.to_string());
                    }
                }
            }
        }
    }
    funcs
}

/// Analyses a disassembly: deepest paths from `main` and from the interrupt vectors.
pub fn analyze(disassembly: &str) -> StackAnalysis {
    let funcs = parse(disassembly);
    let mut analysis = StackAnalysis::default();
    for (name, f) in &funcs {
        if f.indirect > 0 {
            analysis.indirect.insert(name.clone());
        }
        if f.late_pushes > 0 {
            analysis.late_pushes.insert(name.clone());
        }
        if f.uses_stack_arguments() {
            analysis.stack_arguments.insert(name.clone());
        }
    }
    let mut memo: BTreeMap<String, CallPath> = BTreeMap::new();
    let mut recursive = BTreeSet::new();
    analysis.main = deepest("main", &funcs, &mut memo, &mut Vec::new(), &mut recursive);
    for name in funcs.keys().filter(|n| n.starts_with("__vector_")) {
        let p = deepest(name, &funcs, &mut memo, &mut Vec::new(), &mut recursive);
        if p.bytes > analysis.interrupt.bytes {
            analysis.interrupt = p;
        }
    }
    analysis.recursive = recursive;
    analysis
}

/// Runs `avr-objdump -d` on `elf` and analyses it.
pub fn analyze_elf(elf: &Path) -> Result<StackAnalysis, String> {
    Ok(analyze(&disassemble(elf)?))
}

/// `avr-objdump -d` of `elf`.
pub fn disassemble(elf: &Path) -> Result<String, String> {
    let out = Command::new("avr-objdump")
        .arg("-d")
        .arg(elf)
        .output()
        .map_err(|e| format!("avr-objdump: {e} (apt install binutils-avr)"))?;
    if !out.status.success() {
        return Err(format!(
            "avr-objdump -d {}: {}",
            elf.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn deepest(
    name: &str,
    funcs: &BTreeMap<String, Function>,
    memo: &mut BTreeMap<String, CallPath>,
    active: &mut Vec<String>,
    recursive: &mut BTreeSet<String>,
) -> CallPath {
    if let Some(p) = memo.get(name) {
        return p.clone();
    }
    let Some(f) = funcs.get(name) else {
        return CallPath::default(); // outside the disassembly (absolute address): leaf
    };
    active.push(name.to_string());
    let mut below = CallPath::default();
    for (c, is_call) in f
        .callees
        .iter()
        .map(|c| (c, true))
        .chain(f.jumps.iter().map(|c| (c, false)))
    {
        if active.iter().any(|a| a == c) {
            if is_call {
                recursive.insert(c.clone());
            }
            continue;
        }
        let p = deepest(c, funcs, memo, active, recursive);
        if p.bytes > below.bytes {
            below = p;
        }
    }
    active.pop();
    let mut frames = vec![(name.to_string(), f.own)];
    frames.extend(below.frames);
    let path = CallPath {
        bytes: f.own + below.bytes,
        frames,
    };
    memo.insert(name.to_string(), path.clone());
    path
}

/// `0000013a <main>:` → `main`.
pub(crate) fn label(line: &str) -> Option<&str> {
    let (addr, rest) = line.split_once(" <")?;
    if addr.is_empty() || !addr.bytes().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    rest.strip_suffix(">:")
}

/// An instruction line's fields, `<address>:<TAB><bytes><TAB><mnemonic><TAB><operands>[<TAB>;
/// comment]`: `(address, bytes, mnemonic, operands)`, trimmed, the address without its `:`.
/// E.g. `13a: 0e 94 15 3e call 0x7c2a ; 0x7c2a <f>` → `("13a", "0e 94 15 3e", "call",
/// "0x7c2a")`.
pub(crate) fn fields(line: &str) -> Option<(&str, &str, &str, &str)> {
    let mut parts = line.split('\t');
    let addr = parts.next()?.trim().strip_suffix(':')?;
    let bytes = parts.next()?.trim();
    let mnemonic = parts.next()?.trim();
    let operands = parts.next().unwrap_or("").trim();
    Some((addr, bytes, mnemonic, operands))
}

/// An instruction line's mnemonic and operands (see [`fields`]), e.g. `("call", "0x7c2a")`.
fn instruction(line: &str) -> Option<(&str, &str)> {
    fields(line).map(|(_, _, mnemonic, operands)| (mnemonic, operands))
}

/// The function a branch lands in: the `<name>` or `<name+0x12>` comment; `""` for
/// a target without a symbol.
fn target(line: &str) -> Option<&str> {
    let start = line.rfind('<')?;
    let end = line.rfind('>')?;
    let inner = line.get(start + 1..end)?;
    Some(inner.split('+').next().unwrap_or(inner))
}

/// The address a branch, call or jump lands at, from its comment: `… ; 0x7c2a <f+0x2>` →
/// `0x7c2a`.
pub(crate) fn target_address(line: &str) -> Option<u32> {
    let (_, comment) = line.rsplit_once("; 0x")?;
    let hex = comment.split(|c: char| !c.is_ascii_hexdigit()).next()?;
    u32::from_str_radix(hex, 16).ok()
}

/// The displacement of a `Y+q` operand: `r24, Y+53` (ldd) or `Y+53, r24` (std) → 53.
fn y_slot(operands: &str) -> Option<u32> {
    let rest = operands.split_once("Y+")?.1;
    let digits: &str = rest.split(|c: char| !c.is_ascii_digit()).next()?;
    digits.parse().ok()
}

/// `r28, 0x5B` → 0x5B; `r28, 91` → 91.
fn immediate(operands: &str) -> u32 {
    let v = operands
        .split(',')
        .nth(1)
        .map(|s| s.split(';').next().unwrap_or(s).trim())
        .unwrap_or("");
    match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16).unwrap_or(0),
        None => v.parse().unwrap_or(0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made image: main (2 pushes, frame 0x0105) → a (1 push) → b (frame 0x10 via
    /// sbiw) ; main → c+0x4 (no frame); vector 3 → isr (3 pushes).
    const IMAGE: &str = "\
00000100 <main>:
     100:\t0f 93 \tpush\tr16
     102:\t1f 93 \tpush\tr17
     104:\tcd b7 \tin\tr28, 0x3d\t; 61
     106:\tde b7 \tin\tr29, 0x3e\t; 62
     108:\tc5 50 \tsubi\tr28, 0x05\t; 5
     10a:\td1 40 \tsbci\tr29, 0x01\t; 1
     10c:\t0e 94 00 02 \tcall\t0x200\t; 0x200 <a>
     110:\t0e 94 06 04 \tcall\t0x406\t; 0x406 <c+0x4>
     114:\t08 95 \tret

00000200 <a>:
     200:\t0f 93 \tpush\tr16
     202:\t0e 94 00 03 \tcall\t0x300\t; 0x300 <b>
     206:\t0f 91 \tpop\tr16
     208:\t08 95 \tret

00000300 <b>:
     2fc:\tcd b7 \tin\tr28, 0x3d\t; 61
     2fe:\tde b7 \tin\tr29, 0x3e\t; 62
     300:\t60 97 \tsbiw\tr28, 0x10\t; 16
     302:\t60 97 \tsbiw\tr28, 0x20\t; moves Y only: not frame
     304:\t08 95 \tret

00000402 <c>:
     402:\t00 00 \tnop
     404:\t00 00 \tnop
     406:\t08 95 \tret

00000500 <__vector_3>:
     500:\t1f 92 \tpush\tr1
     502:\t0f 92 \tpush\tr0
     504:\t8f 93 \tpush\tr24
     506:\t18 95 \treti
";

    #[test]
    fn frames_calls_and_paths_of_a_hand_made_image() {
        let funcs = parse(IMAGE);
        assert_eq!(funcs["main"].own, 3 + 2 + 0x105);
        assert_eq!(funcs["a"].own, 3 + 1);
        assert_eq!(funcs["b"].own, 3 + 0x10);
        assert_eq!(funcs["c"].own, 3);
        assert_eq!(
            funcs["main"].callees,
            BTreeSet::from(["a".to_string(), "c".to_string()])
        );
        let r = analyze(IMAGE);
        assert_eq!(r.main.bytes, (3 + 2 + 0x105) + 4 + 19);
        let names: Vec<&str> = r.main.frames.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["main", "a", "b"]);
        assert_eq!(r.interrupt.bytes, 6);
        assert_eq!(r.worst(), r.main.bytes + 6);
        assert!(r.complete());
    }

    /// Arguments above the frame: `args` (2 pushes, 4 reserved) reads `Y+7`, the first byte
    /// above its 6; `inside` reads its own top slot `Y+6`; `pointer` uses Y as a plain
    /// pointer (no frame pointer), where `Y+20` is a field, not a stack slot.
    #[test]
    fn reads_above_the_frame_are_stack_arguments() {
        let image = "\
00000100 <args>:
     100:\t0f 93 \tpush\tr16
     102:\tcf 93 \tpush\tr28
     104:\tcd b7 \tin\tr28, 0x3d\t; 61
     106:\tde b7 \tin\tr29, 0x3e\t; 62
     108:\t24 97 \tsbiw\tr28, 0x04\t; 4
     10a:\t8f 81 \tldd\tr24, Y+7\t; 0x07
     10c:\t08 95 \tret
00000200 <inside>:
     200:\t0f 93 \tpush\tr16
     202:\tcf 93 \tpush\tr28
     204:\tcd b7 \tin\tr28, 0x3d\t; 61
     206:\tde b7 \tin\tr29, 0x3e\t; 62
     208:\t24 97 \tsbiw\tr28, 0x04\t; 4
     20a:\t8e 83 \tstd\tY+6, r24\t; 0x06
     20c:\t08 95 \tret
00000300 <pointer>:
     300:\tec 01 \tmovw\tr28, r24
     302:\t8c 89 \tldd\tr24, Y+20\t; 0x14
     304:\t08 95 \tret
";
        let funcs = parse(image);
        assert_eq!(funcs["args"].below_return, 6);
        assert_eq!(funcs["args"].highest_slot, 7);
        let r = analyze(image);
        assert_eq!(r.stack_arguments, BTreeSet::from(["args".to_string()]));
    }

    #[test]
    fn recursion_and_indirect_calls_are_reported() {
        let image = "\
00000100 <main>:
     100:\t0e 94 00 02 \tcall\t0x200\t; 0x200 <f>
00000200 <f>:
     200:\t09 95 \ticall
     202:\t0e 94 00 01 \tcall\t0x100\t; 0x100 <main>
";
        let r = analyze(image);
        assert!(!r.complete());
        assert!(r.recursive.contains("main"));
        assert!(r.indirect.contains("f"));
    }

    #[test]
    fn a_cycle_of_jumps_is_shared_code_not_recursion() {
        let image = "\
00000100 <main>:
     100:\t0e 94 00 02 \tcall\t0x200\t; 0x200 <g>
00000200 <g>:
     200:\t0f 93 \tpush\tr16
     202:\t0c 94 00 03 \tjmp\t0x300\t; 0x300 <h+0x2>
00000300 <h>:
     300:\t1f 93 \tpush\tr17
     302:\t0c 94 00 02 \tjmp\t0x200\t; 0x200 <g>
";
        let r = analyze(image);
        assert!(r.complete(), "{r:?}");
        // main 3 + g (3 + 1) + h (3 + 1), the jump counted as a call.
        assert_eq!(r.main.bytes, 11);
    }
}
