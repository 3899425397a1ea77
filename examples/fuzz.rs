//! Fuzzes the solver: random bytes → mesh → topology → a few steps, for a while.
//!
//! ```text
//! cargo run --release --example fuzz -- --seconds 600 --seed 7
//! ```
//! Every input goes through [`bevy_cloth::solver::fuzz::fuzz_one`]. A panic or a non-finite
//! value is a finding: the input is printed as hex (and written to `fuzz-finding-<n>.hex`) so
//! it can be added to `tests/fuzz.rs` as a regression test. Ends with one JSON line: cases run,
//! refused with a typed error, simulated, findings. Exits with status 1 if anything was found.
//!
//! This is the stable-Rust equivalent of a `cargo fuzz` target: it needs no nightly compiler
//! and mutates byte strings by growing, flipping and splicing the inputs that got furthest
//! (were simulated), a crude coverage proxy.

use std::collections::BTreeMap;
use std::panic;
use std::time::{Duration, Instant};

use bevy_cloth::solver::fuzz::{FuzzOutcome, fuzz_one};

/// xorshift64*: a tiny deterministic generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
}

fn main() {
    let seconds: f64 = arg("--seconds")
        .and_then(|s| s.parse().ok())
        .unwrap_or(60.0);
    let seed: u64 = arg("--seed").and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let start = Instant::now();
    let budget = Duration::from_secs_f64(seconds);
    let mut pool: Vec<Vec<u8>> = vec![vec![0; 16]];
    let mut cases = 0u64;
    let mut refused: BTreeMap<String, u64> = BTreeMap::new();
    let mut simulated = 0u64;
    let mut recoveries = 0u64;
    let mut findings = 0u64;
    panic::set_hook(Box::new(|_| {}));
    while start.elapsed() < budget {
        // Mutate an input from the pool, or make a fresh one.
        let mut input = if rng.below(4) == 0 {
            (0..rng.below(400)).map(|_| rng.next() as u8).collect()
        } else {
            pool[rng.below(pool.len())].clone()
        };
        for _ in 0..1 + rng.below(8) {
            match rng.below(4) {
                0 if !input.is_empty() => {
                    let i = rng.below(input.len());
                    input[i] ^= 1 << rng.below(8);
                }
                1 if !input.is_empty() => {
                    let i = rng.below(input.len());
                    input[i] = rng.next() as u8;
                }
                2 => input.extend((0..rng.below(32)).map(|_| rng.next() as u8)),
                _ => {
                    let other = &pool[rng.below(pool.len())];
                    if !other.is_empty() && !input.is_empty() {
                        let at = rng.below(input.len());
                        let from = rng.below(other.len());
                        let len = rng.below(other.len() - from);
                        input.truncate(at);
                        input.extend_from_slice(&other[from..from + len]);
                    }
                }
            }
        }
        cases += 1;
        let outcome = panic::catch_unwind(|| fuzz_one(&input));
        let bad = match outcome {
            Ok(FuzzOutcome::Refused(e)) => {
                // Group by the message without its numbers.
                let key: String = e
                    .split_whitespace()
                    .filter(|w| {
                        !w.starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '[')
                    })
                    .take(6)
                    .collect::<Vec<_>>()
                    .join(" ");
                *refused.entry(key).or_default() += 1;
                false
            }
            Ok(FuzzOutcome::Simulated { recoveries: r, .. }) => {
                simulated += 1;
                recoveries += u64::from(r);
                if pool.len() < 4096 {
                    pool.push(input.clone());
                }
                // A reset means a NaN was born inside the solver: a finding too.
                r > 0
            }
            Ok(FuzzOutcome::NonFinite { .. }) | Err(_) => true,
        };
        if bad {
            findings += 1;
            let hex: String = input.iter().map(|b| format!("{b:02x}")).collect();
            eprintln!(
                "finding {findings}: {outcome:?} for input {hex}",
                outcome = panic::catch_unwind(|| fuzz_one(&input)).map_err(|_| "panic")
            );
            std::fs::write(format!("fuzz-finding-{findings}.hex"), &hex).ok();
        }
    }
    let refused_json: Vec<String> = refused
        .iter()
        .map(|(k, v)| format!("\"{}\":{v}", k.replace('"', "'")))
        .collect();
    println!(
        "{{\"cases\":{cases},\"seconds\":{:.0},\"seed\":{seed},\"simulated\":{simulated},\"recoveries\":{recoveries},\"findings\":{findings},\"refused\":{{{}}}}}",
        start.elapsed().as_secs_f64(),
        refused_json.join(",")
    );
    if findings > 0 {
        std::process::exit(1);
    }
}
