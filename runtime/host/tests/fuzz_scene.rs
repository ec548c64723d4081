//! Property-based fuzzing of the scene parser (issue 13): the repository's
//! own scene files, mutated — characters flipped, inserted and cut, a value
//! replaced by a hostile one (huge, negative, NaN, inf, 1e308, an empty
//! string, a table where a number goes), a line duplicated (duplicate keys)
//! or dropped. Every case must parse or fail with one error whose message is
//! a single non-empty line — never a panic — and a parsed scene must give
//! its model and render tables back as TOML.
//!
//! `cargo test -p voxflex-runtime --test fuzz_scene` runs 5,000 cases
//! (seeded); `VOXFLEX_FUZZ_CASES` and `VOXFLEX_FUZZ_SEED` change the count
//! and the cases.

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::path::Path;
use voxflex_runtime::scene::Scene;

const SEEDS: &[&str] = &[
    include_str!("../../../configs/demo.toml"),
    include_str!("../../../configs/chainmail-head.toml"),
    "[scene]\nname = \"carve\"\nframes = 2\ndt_s = 0.01\n[volume]\nsource = \"phantom:cube\"\n\
     dims = [40, 40, 40]\n[model]\nplugin = \"corotational-fem\"\n[model.params]\n\
     proxy = { kind = \"uniform\", step = 2 }\nmaterials = [{ range = [50, 200], youngs_modulus = 3000 }]\n\
     [[interaction]]\nframe = 1\nkind = \"carve\"\ncentre = [0, 0, 0]\nradius = 12\n\
     [resample]\nbackground = -1000\nmax_output_factor = 2\n",
];

const HOSTILE: &[&str] = &[
    "0",
    "-1",
    "18446744073709551616",
    "9223372036854775807",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "0.0",
    "\"\"",
    "\"phantom:\"",
    "[]",
    "{}",
    "[1e308, 1e308, 1e308]",
    "[0, 0, 0]",
    "[100000, 100000, 100000]",
    "\"../../../../etc/passwd\"",
    "true",
];

#[derive(Clone, Debug)]
enum Mutation {
    Flip(usize, u8),
    Insert(usize, String),
    Truncate(usize),
    /// Replace the value of the n-th `key = value` line.
    Value(usize, usize),
    DuplicateLine(usize),
    DropLine(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        1 => (any::<usize>(), 1..=127u8).prop_map(|(i, x)| Mutation::Flip(i, x)),
        1 => (any::<usize>(), "[\\[\\]{}=\"#,.\n a-z0-9]{1,8}")
            .prop_map(|(i, s)| Mutation::Insert(i, s)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
        4 => (any::<usize>(), any::<usize>()).prop_map(|(l, v)| Mutation::Value(l, v)),
        1 => any::<usize>().prop_map(Mutation::DuplicateLine),
        1 => any::<usize>().prop_map(Mutation::DropLine),
    ]
}

fn apply(text: &str, m: &Mutation) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let n = lines.len().max(1);
    match m {
        Mutation::Flip(i, x) => {
            let mut b = text.as_bytes().to_vec();
            if !b.is_empty() {
                let k = i % b.len();
                b[k] ^= x;
            }
            return String::from_utf8_lossy(&b).into_owned();
        }
        Mutation::Insert(i, s) => {
            let mut b = text.as_bytes().to_vec();
            let at = i % (b.len() + 1);
            b.splice(at..at, s.bytes());
            return String::from_utf8_lossy(&b).into_owned();
        }
        Mutation::Truncate(i) => {
            let b = text.as_bytes();
            return String::from_utf8_lossy(&b[..i % (b.len() + 1)]).into_owned();
        }
        Mutation::Value(l, v) => {
            let keyed: Vec<usize> = (0..lines.len())
                .filter(|&i| lines[i].contains('=') && !lines[i].trim_start().starts_with('#'))
                .collect();
            if !keyed.is_empty() {
                let i = keyed[l % keyed.len()];
                let key = lines[i].split('=').next().unwrap_or("").to_owned();
                lines[i] = format!("{key}= {}", HOSTILE[v % HOSTILE.len()]);
            }
        }
        Mutation::DuplicateLine(l) if !lines.is_empty() => {
            let line = lines[l % n].clone();
            lines.insert(l % n, line);
        }
        Mutation::DropLine(l) if !lines.is_empty() => {
            lines.remove(l % n);
        }
        _ => {}
    }
    lines.join("\n")
}

fn env_or<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn fuzz_scene_parser() {
    let cases: u32 = env_or("VOXFLEX_FUZZ_CASES", 5000);
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&env_or("VOXFLEX_FUZZ_SEED", 13u64).to_le_bytes());
    let mut runner = TestRunner::new_with_rng(
        Config {
            cases,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &key),
    );
    let parsed = std::cell::Cell::new(0u32);
    let strategy = (any::<usize>(), prop::collection::vec(mutation(), 1..=3));
    let result = runner.run(&strategy, |(s, ms)| {
        let mut text = SEEDS[s % SEEDS.len()].to_owned();
        for m in &ms {
            text = apply(&text, m);
        }
        match Scene::parse(&text, Path::new("fuzz.toml")) {
            Ok(scene) => {
                parsed.set(parsed.get() + 1);
                let _ = scene.model_params_toml();
                let _ = scene.render_params_toml();
            }
            Err(e) => {
                let m = e.to_string();
                prop_assert!(!m.trim().is_empty(), "empty error");
                prop_assert!(!m.contains('\n'), "error spans several lines: {m}");
            }
        }
        Ok(())
    });
    if let Err(e) = result {
        panic!("scene parser: {e}");
    }
    let ok = parsed.get();
    eprintln!(
        "scene parser: {cases} cases, {ok} parsed, {} refused",
        cases - ok
    );
    // Mutations that never parse, or never fail, test nothing.
    assert!(
        ok > cases / 50 && ok < cases - cases / 50,
        "{ok} of {cases} parsed"
    );
}
