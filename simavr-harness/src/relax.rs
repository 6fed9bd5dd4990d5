//! Proof that linker relaxation (`avr-ld --relax`) changed no control flow: two disassemblies
//! of the same image (`avr-objdump -d`), linked without and with relaxation, compared
//! function by function.
//!
//! Relaxation may only:
//! - turn `call` into `rcall` and `jmp` into `rjmp` (target within ±4 KB);
//! - turn `call X; ret` into `jmp X` (the `ret` dropped only when nothing branches to it);
//! - turn `call X; ret` into `jmp X; ret` (it does when something branches to the `ret`, and
//!   sometimes when nothing does: a `ret` after a `jmp` that nothing branches to is dead);
//! - keep the 4-byte vector table entries as `rjmp X; nop`.
//!
//! A `ret` after a skip instruction (`cpse`, `sbrc`, `sbrs`, `sbic`, `sbis`) and the call or
//! jump is reachable (the skip jumps over the call to it) and must stay. Everything else must
//! be equal: every instruction, and every branch, call and jump target
//! as (function, instruction index) after those rewrites, so that a relative branch that
//! relaxation failed to adjust (it moves code by deleting bytes) is caught. Absolute
//! operands of other instructions (data addresses, immediates) must match byte for byte,
//! except in `__do_copy_data`, which loads the flash address of the `.data` image (it moves
//! with the shorter `.text`). The data that follows the vector table inside `__vectors`
//! (progmem constants, disassembled as nonsense instructions) is compared as bytes.

use std::collections::{BTreeMap, BTreeSet};

use crate::stack::{fields, label, target_address};

/// Skip instructions: they jump over the next instruction.
const SKIPS: &[&str] = &["cpse", "sbrc", "sbrs", "sbic", "sbis"];

/// Functions whose operands legitimately change with the size of `.text`.
const MOVES_WITH_TEXT: &[&str] = &["__do_copy_data"];

/// One instruction: mnemonic (`rcall`/`rjmp` written as `call`/`jmp`), and either its
/// target `(function, index)` or its operands.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Op {
    /// A branch, call or jump to a labelled address.
    To(String, (String, usize)),
    /// Anything else (or a target outside every function): mnemonic and operands.
    Plain(String, String),
}

/// A disassembly as functions of instructions `(address, mnemonic, operands, target)`.
type Functions = BTreeMap<String, Vec<(u32, String, String, Option<u32>)>>;

/// The symbol of the interrupt vector table, followed by progmem data.
const VECTORS: &str = "__vectors";

fn parse(disassembly: &str) -> Functions {
    let mut funcs = Functions::new();
    let mut current: Option<String> = None;
    for line in disassembly.lines() {
        if let Some(name) = label(line) {
            current = Some(name.to_string());
            funcs.entry(name.to_string()).or_default();
            continue;
        }
        let Some(name) = &current else { continue };
        let Some((addr, bytes, mnemonic, operands)) = fields(line) else {
            continue;
        };
        let Ok(addr) = u32::from_str_radix(addr, 16) else {
            continue;
        };
        let operands = operands.to_string();
        let mnemonic = match mnemonic {
            "rcall" => "call",
            "rjmp" => "jmp",
            m => m,
        };
        let is_branch = matches!(mnemonic, "call" | "jmp") || mnemonic.starts_with("br");
        let target = if is_branch {
            target_address(line)
        } else {
            None
        };
        if let Some(f) = funcs.get_mut(name) {
            f.push((addr, mnemonic.to_string(), operands.clone(), target));
            if name == VECTORS {
                // The bytes, for the data after the table (see `split_vectors`).
                f.push((addr, "bytes".into(), format!("{bytes} {operands}"), None));
            }
        }
    }
    split_vectors(&mut funcs);
    funcs
}

/// Leaves the vector table (its `jmp` / `rjmp` + `nop` entries) in `__vectors` and moves the
/// data after it into `__vectors (data)`, one pseudo-instruction holding its bytes.
fn split_vectors(funcs: &mut Functions) {
    let Some(all) = funcs.remove(VECTORS) else {
        return;
    };
    let (mut table, mut data) = (Vec::new(), String::new());
    let mut in_table = true;
    for (addr, m, operands, target) in all {
        if m == "bytes" {
            if !in_table {
                data += &operands;
                data.push(' ');
            }
            continue;
        }
        in_table &= matches!(m.as_str(), "jmp" | "nop");
        if in_table {
            table.push((addr, m, operands, target));
        }
    }
    funcs.insert(VECTORS.into(), table);
    funcs.insert(
        format!("{VECTORS} (data)"),
        vec![(0, "data".into(), data, None)],
    );
}

/// The functions with targets resolved and the allowed rewrites undone (see the module docs).
fn canonical(funcs: &Functions) -> BTreeMap<String, Vec<Op>> {
    let mut at: BTreeMap<u32, (String, usize)> = BTreeMap::new();
    for (name, ins) in funcs {
        for (i, (addr, ..)) in ins.iter().enumerate() {
            at.insert(*addr, (name.clone(), i));
        }
    }
    let raw: BTreeMap<String, Vec<Op>> = funcs
        .iter()
        .map(|(name, ins)| {
            let ops = ins
                .iter()
                .map(|(_, m, operands, t)| match t.and_then(|t| at.get(&t)) {
                    Some(to) => Op::To(m.clone(), to.clone()),
                    None => Op::Plain(m.clone(), operands.clone()),
                })
                .collect();
            (name.clone(), ops)
        })
        .collect();
    let targets: BTreeSet<(String, usize)> = raw
        .values()
        .flatten()
        .filter_map(|op| match op {
            Op::To(_, to) => Some(to.clone()),
            Op::Plain(..) => None,
        })
        .collect();
    // Collapse the rewritable pairs, remembering where each old index went.
    let mut remap: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    let mut collapsed: BTreeMap<String, Vec<Op>> = BTreeMap::new();
    for (name, ops) in &raw {
        let (mut out, mut map) = (Vec::new(), Vec::new());
        let mut k = 0;
        while let Some(op) = ops.get(k) {
            map.push(out.len());
            let next = ops.get(k + 1);
            let skipped = k
                .checked_sub(1)
                .and_then(|i| ops.get(i))
                .is_some_and(|p| matches!(p, Op::Plain(m, _) if SKIPS.contains(&m.as_str())));
            let pair = !targets.contains(&(name.clone(), k + 1))
                && !skipped
                && match (op, next) {
                    (Op::To(m, _), Some(Op::Plain(n, _)))
                        if (m == "call" || m == "jmp") && n == "ret" =>
                    {
                        true
                    }
                    (Op::To(m, _), Some(Op::Plain(n, o))) if m == "jmp" && n == "nop" => {
                        o.is_empty()
                    }
                    _ => false,
                };
            let tail_call = matches!((op, next), (Op::To(m, _), Some(Op::Plain(n, _))) if m == "call" && n == "ret");
            out.push(match (op, pair || tail_call) {
                (Op::To(_, to), true) => Op::To("jmp".into(), to.clone()),
                (op, _) => op.clone(),
            });
            if pair {
                map.push(out.len() - 1);
                k += 1;
            }
            k += 1;
        }
        remap.insert(name.clone(), map);
        collapsed.insert(name.clone(), out);
    }
    collapsed
        .into_iter()
        .map(|(name, ops)| {
            let ops = ops
                .into_iter()
                .map(|op| match op {
                    Op::To(m, (f, i)) => {
                        let i = remap.get(&f).and_then(|r| r.get(i)).copied().unwrap_or(i);
                        Op::To(m, (f, i))
                    }
                    plain => plain,
                })
                .collect();
            (name, ops)
        })
        .collect()
}

/// Compares the disassembly `plain` (linked without relaxation) with `relaxed`: the
/// functions whose control flow differs, each with its first difference (empty when
/// relaxation changed nothing but the allowed rewrites).
pub fn compare(plain: &str, relaxed: &str) -> Vec<String> {
    let (a, b) = (canonical(&parse(plain)), canonical(&parse(relaxed)));
    let mut problems = Vec::new();
    for (name, ops) in &a {
        if MOVES_WITH_TEXT.contains(&name.as_str()) {
            continue;
        }
        let Some(other) = b.get(name) else {
            problems.push(format!("{name}: missing after relaxation"));
            continue;
        };
        if ops == other {
            continue;
        }
        let first = ops.iter().zip(other).position(|(x, y)| x != y);
        problems.push(match first {
            Some(i) => format!(
                "{name}: instruction {i}: {:?} became {:?}",
                ops.get(i),
                other.get(i)
            ),
            None => format!("{name}: {} instructions became {}", ops.len(), other.len()),
        });
    }
    for name in b.keys().filter(|n| !a.contains_key(*n)) {
        problems.push(format!("{name}: new after relaxation"));
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disassembly in `avr-objdump -d`'s layout from `(address, mnemonic, operands)` rows
    /// per function; branch operands name their target address as `@0xADDR`.
    /// Functions as `(name, start address, [(mnemonic, operands)])`.
    type Listing<'a> = [(&'a str, u32, &'a [(&'a str, &'a str)])];

    fn dis(funcs: &Listing) -> String {
        let mut s = String::new();
        let mut symbols: Vec<(u32, &str)> = funcs.iter().map(|(n, a, _)| (*a, *n)).collect();
        symbols.sort();
        for (name, start, ins) in funcs {
            s += &format!("{start:08x} <{name}>:\n");
            let mut addr = *start;
            for (m, o) in ins.iter() {
                let line = match o.strip_prefix('@') {
                    Some(t) => {
                        let t = u32::from_str_radix(t.trim_start_matches("0x"), 16).unwrap();
                        let (base, sym) = symbols.iter().rev().find(|(a, _)| *a <= t).unwrap();
                        let off = t - base;
                        let at = if off == 0 {
                            sym.to_string()
                        } else {
                            format!("{sym}+0x{off:x}")
                        };
                        format!("{addr:>8x}:\t00 00 \t{m}\t0x{t:x}\t; 0x{t:x} <{at}>\n")
                    }
                    None => format!("{addr:>8x}:\t00 00 \t{m}\t{o}\n"),
                };
                s += &line;
                addr += if matches!(*m, "call" | "jmp") { 4 } else { 2 };
            }
            s += "\n";
        }
        s
    }

    fn plain() -> String {
        dis(&[
            (
                "f",
                0x100,
                &[
                    ("ldi", "r24, 0x01"),
                    ("breq", "@0x108"),
                    ("call", "@0x200"),
                    ("ret", ""),
                ],
            ),
            ("g", 0x200, &[("ret", "")]),
        ])
    }

    #[test]
    fn identical_images_pass() {
        assert!(compare(&plain(), &plain()).is_empty());
    }

    #[test]
    fn short_calls_pass() {
        let relaxed = dis(&[
            (
                "f",
                0x100,
                &[
                    ("ldi", "r24, 0x01"),
                    ("breq", "@0x106"),
                    ("rcall", "@0x1fe"),
                    ("ret", ""),
                ],
            ),
            ("g", 0x1fe, &[("ret", "")]),
        ]);
        assert_eq!(compare(&plain(), &relaxed), Vec::<String>::new());
    }

    #[test]
    fn call_ret_to_jmp_passes_only_when_the_ret_is_no_target() {
        let p = dis(&[
            (
                "f",
                0x100,
                &[("ldi", "r24, 0x01"), ("call", "@0x200"), ("ret", "")],
            ),
            ("g", 0x200, &[("ret", "")]),
        ]);
        let r = dis(&[
            ("f", 0x100, &[("ldi", "r24, 0x01"), ("rjmp", "@0x1fe")]),
            ("g", 0x1fe, &[("ret", "")]),
        ]);
        assert!(compare(&p, &r).is_empty());
        // In `plain()` the `ret` is the `breq`'s target: it may not disappear.
        let dropped = dis(&[
            (
                "f",
                0x100,
                &[("ldi", "r24, 0x01"), ("breq", "@0x104"), ("jmp", "@0x200")],
            ),
            ("g", 0x200, &[("ret", "")]),
        ]);
        assert_eq!(compare(&plain(), &dropped).len(), 1);
        // ... but its call may become a jump.
        let kept = dis(&[
            (
                "f",
                0x100,
                &[
                    ("ldi", "r24, 0x01"),
                    ("breq", "@0x108"),
                    ("jmp", "@0x200"),
                    ("ret", ""),
                ],
            ),
            ("g", 0x200, &[("ret", "")]),
        ]);
        assert!(compare(&plain(), &kept).is_empty());
    }

    #[test]
    fn a_dead_ret_kept_after_the_jump_passes_but_one_a_skip_reaches_must_stay() {
        let g = ("g", 0x200, &[("ret", "")][..]);
        let p = dis(&[("f", 0x100, &[("call", "@0x200"), ("ret", "")]), g]);
        // avr-ld turned the call into a jump and kept the `ret`, which nothing reaches.
        let kept = dis(&[("f", 0x100, &[("jmp", "@0x200"), ("ret", "")]), g]);
        assert!(compare(&p, &kept).is_empty());
        // After a skip, the `ret` is where the skip lands: dropping it is a change.
        let p = dis(&[
            (
                "f",
                0x100,
                &[("sbrs", "r24, 0"), ("call", "@0x200"), ("ret", "")],
            ),
            g,
        ]);
        let dropped = dis(&[("f", 0x100, &[("sbrs", "r24, 0"), ("jmp", "@0x200")]), g]);
        assert_eq!(compare(&p, &dropped).len(), 1);
        let kept = dis(&[
            (
                "f",
                0x100,
                &[("sbrs", "r24, 0"), ("jmp", "@0x200"), ("ret", "")],
            ),
            g,
        ]);
        assert!(compare(&p, &kept).is_empty());
    }

    #[test]
    fn vector_entries_may_shrink_but_the_data_after_them_must_not_change() {
        let table = |entry: &'static [(&'static str, &'static str)], data: &'static str| {
            let mut ins: Vec<(&str, &str)> = entry.to_vec();
            ins.extend([("ori", data), ("ldi", "r24, 0x01")]);
            ins
        };
        let p = table(&[("jmp", "@0x200")], "r19, 0x8E");
        let r = table(&[("rjmp", "@0x1fe"), ("nop", "")], "r19, 0x8E");
        let moved = table(&[("rjmp", "@0x1fe"), ("nop", "")], "r19, 0x8F");
        let image = |v: &[(&str, &str)], g| dis(&[("__vectors", 0, v), ("g", g, &[("ret", "")])]);
        assert!(compare(&image(&p, 0x200), &image(&r, 0x1fe)).is_empty());
        let problems = compare(&image(&p, 0x200), &image(&moved, 0x1fe));
        assert!(
            problems.iter().any(|p| p.starts_with("__vectors (data)")),
            "{problems:?}"
        );
    }

    #[test]
    fn a_branch_left_unadjusted_fails() {
        // The call shrank by 2 bytes but the branch still jumps 10 bytes ahead: it now lands
        // past the `ret`, in `g`.
        let relaxed = dis(&[
            (
                "f",
                0x100,
                &[
                    ("ldi", "r24, 0x01"),
                    ("breq", "@0x10a"),
                    ("rcall", "@0x108"),
                    ("ret", ""),
                ],
            ),
            ("g", 0x108, &[("nop", ""), ("ret", "")]),
        ]);
        let problems = compare(&plain(), &relaxed);
        assert!(problems.iter().any(|p| p.starts_with("f:")), "{problems:?}");
    }

    #[test]
    fn a_changed_operand_fails() {
        let relaxed = dis(&[
            (
                "f",
                0x100,
                &[
                    ("ldi", "r24, 0x02"),
                    ("breq", "@0x106"),
                    ("rcall", "@0x1fe"),
                    ("ret", ""),
                ],
            ),
            ("g", 0x1fe, &[("ret", "")]),
        ]);
        assert_eq!(compare(&plain(), &relaxed).len(), 1);
    }
}
