//! The fuzz target over a fixed corpus (so CI covers it without running the fuzzer), plus
//! every input the fuzzer ever found as a named regression test.
//! Run the fuzzer itself with `cargo run --release --example fuzz -- --seconds 600`.

use bevy_cloth::solver::fuzz::{FuzzOutcome, fuzz_one};

fn sane(input: &[u8]) -> FuzzOutcome {
    let outcome = fuzz_one(input);
    assert!(
        !matches!(outcome, FuzzOutcome::NonFinite { .. }),
        "{outcome:?} for {input:02x?}"
    );
    if let FuzzOutcome::Simulated { recoveries, .. } = outcome {
        assert_eq!(recoveries, 0, "the solver had to reset for {input:02x?}");
    }
    outcome
}

#[test]
fn a_fixed_corpus_of_random_inputs_is_handled() {
    // 20 000 inputs from a fixed xorshift stream, lengths 0..400 (most are refused: random
    // bytes rarely make a valid scene; the fuzz example mutates the ones that get through).
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let (mut refused, mut simulated) = (0, 0);
    for _ in 0..20_000 {
        let len = (next() % 400) as usize;
        let input: Vec<u8> = (0..len).map(|_| next() as u8).collect();
        match sane(&input) {
            FuzzOutcome::Refused(_) => refused += 1,
            FuzzOutcome::Simulated { .. } => simulated += 1,
            FuzzOutcome::NonFinite { .. } => unreachable!(),
        }
    }
    // Both paths are exercised, or the corpus tests nothing.
    assert!(refused > 100, "refused {refused}");
    assert!(simulated > 50, "simulated {simulated}");
}

#[test]
fn empty_and_tiny_inputs() {
    for input in [&[][..], &[0], &[3, 1, 1], &[255; 8]] {
        sane(input);
    }
}
