//! Golden results: the examples' workloads give the hashes checked in at
//! `tests/golden/hashes.toml`, so "a change kept the same bits" is checked by `cargo test`,
//! not stated in a commit message; and the same bits on one thread as on two.

#[path = "../examples/workloads/mod.rs"]
mod workloads;

use serde::Deserialize;

#[derive(Debug, Deserialize)]
struct Golden {
    press: Vec<Press>,
    cut: Vec<Cut>,
}

#[derive(Debug, Deserialize)]
struct Press {
    scene: String,
    tets: usize,
    steps: usize,
    hash: String,
}

#[derive(Debug, Deserialize)]
struct Cut {
    tets: usize,
    localised: bool,
    hash: String,
}

fn golden() -> Golden {
    toml::from_str(include_str!("golden/hashes.toml")).expect("tests/golden/hashes.toml")
}

fn press_hash(p: &Press) -> String {
    let mut sim = workloads::settled(&p.scene, p.tets).expect("the scene");
    workloads::press(&mut sim, p.steps, 0.3, |_, _| {}).expect("the steps");
    format!("{:016x}", workloads::positions_hash(&sim))
}

fn cut_hash(c: &Cut) -> String {
    let mut sim = workloads::settled("chest-wall", c.tets).expect("the scene");
    workloads::cut_along_top(&mut sim, 3, c.localised, |_| {}).expect("the cut");
    format!("{:016x}", workloads::mesh_hash(&sim))
}

/// The cases whose hash is not the golden one, with the hash they gave.
fn changed<T: std::fmt::Debug>(
    cases: &[T],
    hash: impl Fn(&T) -> String,
    golden: impl Fn(&T) -> &str,
) -> Vec<String> {
    cases
        .iter()
        .filter_map(|c| {
            let got = hash(c);
            (got != golden(c)).then(|| format!("{c:?}: got {got}"))
        })
        .collect()
}

#[test]
fn the_press_gives_its_golden_hashes() {
    let failures = changed(&golden().press, press_hash, |p| &p.hash);
    assert!(failures.is_empty(), "changed bits: {failures:#?}");
}

#[test]
fn the_cut_gives_its_golden_hashes() {
    let failures = changed(&golden().cut, cut_hash, |c| &c.hash);
    assert!(failures.is_empty(), "changed bits: {failures:#?}");
}

#[test]
fn one_thread_gives_the_bits_of_two() {
    let g = golden();
    let largest = |scene: &str| {
        g.press
            .iter()
            .filter(|p| p.scene == scene)
            .max_by_key(|p| p.tets)
            .expect("a press")
    };
    let (press, press_fem) = (largest("chest-wall"), largest("chest-wall-fem"));
    let cut = g.cut.iter().max_by_key(|c| c.tets).expect("a cut");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    assert_eq!(one.install(|| press_hash(press)), press.hash);
    assert_eq!(one.install(|| press_hash(press_fem)), press_fem.hash);
    assert_eq!(one.install(|| cut_hash(cut)), cut.hash);
}
