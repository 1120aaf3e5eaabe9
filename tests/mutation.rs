//! Damaged input never panics, aborts or hangs a parser of user files or network input
//! (issue 32): a bounded, deterministic mutation test.
//!
//! Each parser's valid sample files (the checked-in data, files written with the crate's own
//! writers, a real session's recording) are seeds. A small seeded mutator (splitmix64) damages
//! them: bit flips, runs of 0xff / 0x00, truncation, bytes inserted and deleted, duplicated
//! slices, interesting integers and floats written into binary headers, and for text formats
//! numbers replaced by huge, negative, NaN or `1e309` values and lines deleted or duplicated.
//! Each parser's cases run in a child process (this test binary again, running only that
//! parser's test), so an abort fails that parser's test, with its reproducer, and not the
//! others. Every case runs under `catch_unwind` on a worker thread that a watchdog times: a
//! panic, a case taking longer than [`HANG`] or an accepted input that breaks the parser's
//! promises (see `mutation/targets.rs`) fails the test. A failing input is saved as
//! `target/mutation-failures/<parser>-<case>.<ext>` (TetGen: `.node` + `.ele`); the input in
//! flight is kept as `<parser>-inflight.*` so that even an abort (an allocation failure, a
//! stack overflow) leaves its reproducer (`<parser>-<case>-abort.<ext>`). Allocations larger
//! than [`MAX_ALLOCATION`] fail (and so abort) instead of exhausting the machine.
//!
//! Each test also runs the seeds themselves (they must be accepted) and every file under
//! `tests/fuzz-regressions/<parser>/` (inputs that once crashed a parser; they must not panic).
//!
//! Environment: `CUTLAB_MUTATIONS=N` runs N mutated cases per parser instead of the default
//! (thousands, sized for CI: well under a minute for the whole file in release on two cores);
//! `CUTLAB_MUTATION_ONLY=<parser>:<case>` runs just that case and saves its input (to
//! reproduce a failure from its printed case number); `CUTLAB_WRITE_CORPUS=DIR` only writes
//! every parser's seeds to `DIR/<parser>/` (the starting corpus of the fuzz targets).
//!
//! The same parser entry points are cargo-fuzz targets in `fuzz/` (see `fuzz/README.md`).

#[path = "mutation/recording_targets.rs"]
mod recording_targets;
#[path = "mutation/station_targets.rs"]
mod station_targets;
#[path = "mutation/targets.rs"]
mod targets;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use cutlab_sim::Point3;

/// A case that takes longer than this is a hang.
const HANG: Duration = Duration::from_secs(10);

/// Allocations above this fail (an abort) instead of taking the machine's memory.
const MAX_ALLOCATION: usize = 1 << 30;

#[allow(unsafe_code)]
mod capped_allocator {
    //! The system allocator with a ceiling on a single allocation: a parser that believes a
    //! damaged length field asks for gigabytes, and on a machine with overcommit that can
    //! succeed and take everyone's memory; here it fails at once, which aborts the test with
    //! "memory allocation of N bytes failed" and the in-flight input on disk.
    use std::alloc::{GlobalAlloc, Layout, System};

    #[derive(Debug)]
    pub struct Capped;

    // SAFETY: every call is forwarded to the system allocator unchanged, or refused with a
    // null pointer, which the `GlobalAlloc` contract allows for any request.
    unsafe impl GlobalAlloc for Capped {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            if layout.size() > super::MAX_ALLOCATION {
                return std::ptr::null_mut();
            }
            // SAFETY: the caller's guarantees for `layout` are passed on.
            unsafe { System.alloc(layout) }
        }

        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            if layout.size() > super::MAX_ALLOCATION {
                return std::ptr::null_mut();
            }
            // SAFETY: as for `alloc`.
            unsafe { System.alloc_zeroed(layout) }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: `ptr` came from `System` with this layout.
            unsafe { System.dealloc(ptr, layout) }
        }

        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            if new_size > super::MAX_ALLOCATION {
                return std::ptr::null_mut();
            }
            // SAFETY: `ptr` came from `System` with `layout`; the caller's guarantees for
            // `new_size` are passed on.
            unsafe { System.realloc(ptr, layout, new_size) }
        }
    }
}

#[global_allocator]
static ALLOCATOR: capped_allocator::Capped = capped_allocator::Capped;

// ---------------------------------------------------------------------------------------
// The mutator
// ---------------------------------------------------------------------------------------

/// splitmix64: small, fast, and the same sequence everywhere.
#[derive(Debug, Clone)]
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(seed)
    }

    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }

    /// Uniform in `1..=n`, small values much more often (for lengths).
    fn small(&mut self, n: usize) -> usize {
        let n = n.max(1);
        let bits = 1 + self.below(usize::BITS as usize - n.leading_zeros() as usize);
        1 + self.below((1usize << bits.min(63)).min(n))
    }

    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// Number texts that parsers of counts, indices and coordinates get wrong.
const NUMBERS: &[&str] = &[
    "1e309",
    "-1e309",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "-0",
    "1",
    "2",
    "3",
    "4",
    "10",
    "0.5",
    "-2.5",
    "1e300",
    "-1e300",
    "1e-320",
    "1e154",
    "255",
    "256",
    "65535",
    "65536",
    "2147483647",
    "2147483648",
    "-2147483649",
    "4294967295",
    "4294967296",
    "1000000000",
    "9223372036854775807",
    "9223372036854775808",
    "-9223372036854775809",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999999999",
    "0x10",
    "1e",
    "",
];

/// Integers and floats written into binary fields.
fn binary_value(rng: &mut Rng) -> Vec<u8> {
    let ints: [u64; 16] = [
        0,
        1,
        2,
        3,
        0x7f,
        0x80,
        0xff,
        0x7fff,
        0x8000,
        0xffff,
        0x7fff_ffff,
        0x8000_0000,
        0xffff_ffff,
        0x7fff_ffff_ffff_ffff,
        0x8000_0000_0000_0000,
        u64::MAX,
    ];
    let floats: [f64; 9] = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        0.0,
        -1.0,
        1e30,
        -1e30,
        f64::MIN_POSITIVE,
        f64::MAX,
    ];
    let width = *rng.pick(&[1usize, 2, 4, 8]);
    let big_endian = rng.below(2) == 0;
    let mut bytes = if width >= 4 && rng.below(3) == 0 {
        let f = *rng.pick(&floats);
        if width == 4 {
            (f as f32).to_le_bytes().to_vec()
        } else {
            f.to_le_bytes().to_vec()
        }
    } else {
        let mut v = *rng.pick(&ints);
        if rng.below(4) == 0 {
            v = v.wrapping_add(rng.below(3) as u64).wrapping_sub(1);
        }
        v.to_le_bytes()[..width].to_vec()
    };
    if big_endian {
        bytes.reverse();
    }
    bytes
}

/// Where a number starts at or after a random offset (wrapping around), and where it ends.
fn find_number(rng: &mut Rng, buf: &[u8]) -> Option<(usize, usize)> {
    let n = buf.len();
    if n == 0 {
        return None;
    }
    let start = rng.below(n);
    let is_num = |b: u8| b.is_ascii_digit() || matches!(b, b'.' | b'e' | b'E' | b'+' | b'-');
    for k in 0..n {
        let i = (start + k) % n;
        let b = buf[i];
        let starts = b.is_ascii_digit()
            || (matches!(b, b'-' | b'+' | b'.') && buf.get(i + 1).is_some_and(u8::is_ascii_digit));
        let after_word = i > 0 && (buf[i - 1].is_ascii_alphanumeric() || is_num(buf[i - 1]));
        if starts && !after_word {
            let mut end = i + 1;
            while end < n && is_num(buf[end]) {
                end += 1;
            }
            return Some((i, end));
        }
    }
    None
}

/// Byte ranges of the lines of `buf` (each with its line break).
fn line_spans(buf: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut start = 0;
    for (i, &b) in buf.iter().enumerate() {
        if b == b'\n' {
            spans.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < buf.len() {
        spans.push((start, buf.len()));
    }
    spans
}

/// One random damage to `buf`.
fn mutate_once(rng: &mut Rng, buf: &mut Vec<u8>, text: bool) {
    let len = buf.len();
    let op = rng.below(if text { 12 } else { 9 });
    match op {
        // bit flips
        0 => {
            if len > 0 {
                for _ in 0..rng.small(8) {
                    let i = rng.below(len);
                    buf[i] ^= 1 << rng.below(8);
                }
            }
        }
        // runs of 0xff / 0x00 overwritten
        1 | 2 => {
            if len > 0 {
                let at = rng.below(len);
                let n = rng.small(64).min(len - at);
                let fill = if op == 1 { 0xff } else { 0x00 };
                buf[at..at + n].fill(fill);
            }
        }
        // truncation
        3 => buf.truncate(rng.below(len + 1)),
        // random bytes inserted
        4 => {
            let at = rng.below(len + 1);
            let n = rng.small(32);
            let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
            buf.splice(at..at, bytes);
        }
        // a range deleted
        5 => {
            if len > 0 {
                let at = rng.below(len);
                let n = rng.small(512).min(len - at);
                buf.drain(at..at + n);
            }
        }
        // a slice duplicated elsewhere
        6 => {
            if len > 0 {
                let from = rng.below(len);
                let n = rng.small(2048).min(len - from);
                let slice = buf[from..from + n].to_vec();
                let at = rng.below(len + 1);
                buf.splice(at..at, slice);
            }
        }
        // an interesting binary value, often in the header
        7 | 8 => {
            let value = binary_value(rng);
            let region = if rng.below(2) == 0 { len.min(512) } else { len };
            if region >= value.len() {
                let at = rng.below(region - value.len() + 1);
                buf[at..at + value.len()].copy_from_slice(&value);
            }
        }
        // a number replaced
        9 => {
            if let Some((a, b)) = find_number(rng, buf) {
                let replacement = if rng.below(8) == 0 {
                    // a large random integer, sometimes negative
                    let v = rng.next() >> rng.below(64);
                    if rng.below(2) == 0 {
                        format!("-{v}")
                    } else {
                        v.to_string()
                    }
                } else {
                    (*rng.pick(NUMBERS)).to_owned()
                };
                buf.splice(a..b, replacement.into_bytes());
            }
        }
        // lines deleted
        10 => {
            let lines = line_spans(buf);
            if !lines.is_empty() {
                let first = rng.below(lines.len());
                let last = (first + rng.small(8) - 1).min(lines.len() - 1);
                buf.drain(lines[first].0..lines[last].1);
            }
        }
        // lines duplicated (in place or elsewhere)
        _ => {
            let lines = line_spans(buf);
            if !lines.is_empty() {
                let first = rng.below(lines.len());
                let last = (first + rng.small(8) - 1).min(lines.len() - 1);
                let slice = buf[lines[first].0..lines[last].1].to_vec();
                let at = if rng.below(2) == 0 {
                    lines[first].0
                } else {
                    lines[rng.below(lines.len())].0
                };
                buf.splice(at..at, slice);
            }
        }
    }
}

/// A damaged copy of `seed`: one to a few mutations.
fn mutate(rng: &mut Rng, seed: &[u8], text: bool) -> Vec<u8> {
    let mut out = seed.to_vec();
    let rounds = match rng.below(8) {
        0..=3 => 1,
        4..=5 => 2,
        6 => 3,
        _ => 4 + rng.below(5),
    };
    for _ in 0..rounds {
        mutate_once(rng, &mut out, text);
    }
    out
}

// ---------------------------------------------------------------------------------------
// The harness
// ---------------------------------------------------------------------------------------

/// An input: one byte string per file the parser reads (TetGen: `.node` and `.ele`).
type Input = Vec<Vec<u8>>;

/// One parser under test.
struct Parser {
    name: &'static str,
    /// File extension of each part of an input (for saved failures and regressions).
    parts: &'static [&'static str],
    /// Text format: also mutate numbers and lines.
    text: bool,
    seeds: Vec<Input>,
    /// Mutated cases per run unless `CUTLAB_MUTATIONS` says otherwise.
    default_cases: usize,
    run: Box<dyn Fn(&Input) -> targets::Outcome + Send + Sync>,
}

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn failures_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .map(|t| t.join("mutation-failures"))
        .unwrap_or_else(|| PathBuf::from("target/mutation-failures"));
    std::fs::create_dir_all(&dir).expect("failures directory");
    dir
}

/// A scratch directory of one test (for parsers that read paths).
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("mutation-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch directory");
    dir
}

/// Writes `input` as `dir/stem.<ext>` per part; the paths written.
fn save(dir: &Path, stem: &str, parts: &[&str], input: &Input) -> Vec<PathBuf> {
    input
        .iter()
        .zip(parts)
        .map(|(bytes, ext)| {
            let path = dir.join(format!("{stem}.{ext}"));
            std::fs::write(&path, bytes).expect("save input");
            path
        })
        .collect()
}

/// The regression inputs of a parser: every file in `tests/fuzz-regressions/<name>/`, grouped
/// by stem when the parser reads several files.
fn regressions(name: &str, parts: &[&str]) -> Vec<(String, Input)> {
    let dir = repo().join("tests/fuzz-regressions").join(name);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries.filter_map(|e| Some(e.ok()?.path())).collect();
    files.retain(|p| p.is_file() && p.file_name().is_some_and(|n| n != "README.md"));
    files.sort();
    if parts.len() == 1 {
        return files
            .into_iter()
            .map(|p| {
                let bytes = std::fs::read(&p).expect("regression file");
                (p.display().to_string(), vec![bytes])
            })
            .collect();
    }
    let mut stems: Vec<PathBuf> = files.iter().map(|p| p.with_extension("")).collect();
    stems.dedup();
    stems
        .into_iter()
        .map(|stem| {
            let input = parts
                .iter()
                .map(|ext| std::fs::read(stem.with_extension(ext)).unwrap_or_default())
                .collect();
            (stem.display().to_string(), input)
        })
        .collect()
}

#[derive(Debug, Default)]
struct Counts {
    cases: usize,
    ok: usize,
    err: usize,
    panics: Vec<String>,
}

/// What the watchdog sees of the case in flight.
#[derive(Debug, Default)]
struct InFlight {
    label: String,
    started: Option<Instant>,
    input: Input,
}

/// How a case is labelled: a mutated case by its number, seeds and regressions by name.
#[derive(Debug, Clone)]
enum Case {
    Seed(usize),
    Regression(String),
    Mutated(u64),
}

impl std::fmt::Display for Case {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Case::Seed(i) => write!(f, "seed-{i}"),
            Case::Regression(p) => write!(f, "regression {p}"),
            Case::Mutated(n) => write!(f, "{n}"),
        }
    }
}

/// The input of mutated case `case` of `parser`: a pure function of the two.
fn mutated_input(parser: &Parser, case: u64) -> Input {
    let mut name_hash = cutlab_sim::hash::Fnv1a::default();
    name_hash.bytes(parser.name.as_bytes());
    let name_hash = name_hash.finish();
    let mut rng = Rng::new(name_hash ^ case.wrapping_mul(0xD1B5_4A32_D192_ED03));
    let mut input = rng.pick(&parser.seeds).clone();
    let k = input.len();
    // several files: damage one of them, or (a quarter of the time) each
    let all = k > 1 && rng.below(4) == 0;
    let one = rng.below(k);
    for (i, part) in input.iter_mut().enumerate() {
        if all || i == one {
            *part = mutate(&mut rng, part, parser.text);
        }
    }
    input
}

fn case_count(parser: &Parser) -> u64 {
    std::env::var("CUTLAB_MUTATIONS")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(parser.default_cases as u64)
}

/// Set in the child process that runs one parser's cases.
const CHILD: &str = "CUTLAB_MUTATION_CHILD";

/// Runs the cases of one parser in a child process (this test binary again, running only
/// `test`), so that an abort (an allocation failure, a stack overflow) fails that parser's
/// test with its reproducer instead of ending every test of the file. In the child, builds
/// the parser (seeds) and runs [`check`].
fn isolated(test: &str, parser: impl FnOnce() -> Parser) {
    if std::env::var_os(CHILD).is_some() {
        check(parser());
        // passed: this process's scratch directories (see `scratch`) are not needed
        let suffix = format!("-{}", std::process::id());
        for entry in std::fs::read_dir(env!("CARGO_TARGET_TMPDIR"))
            .into_iter()
            .flatten()
            .flatten()
        {
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with("mutation-") && name.ends_with(&suffix) {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        return;
    }
    let exe = std::env::current_exe().expect("the test binary");
    let out = std::process::Command::new(exe)
        .args([
            test,
            "--exact",
            "--include-ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD, "1")
        .output()
        .expect("run the child test process");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    // the child's report (per-parser counts, failures), shown with --nocapture or on failure
    for line in stderr.lines().filter(|l| !l.trim().is_empty()) {
        eprintln!("{line}");
    }
    if out.status.success() {
        assert!(
            stdout.contains("1 passed"),
            "the child ran no test: {stdout}"
        );
        return;
    }
    // an abort leaves the input in flight on disk: keep it under the case's name
    let failures = failures_dir();
    let prefix = test.split("_never_").next().unwrap_or(test);
    let label = std::fs::read_to_string(failures.join(format!("{prefix}-inflight.txt")))
        .unwrap_or_default();
    let mut saved = Vec::new();
    if let Ok(entries) = std::fs::read_dir(&failures) {
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let Some(ext) = name.strip_prefix(&format!("{prefix}-inflight.")) else {
                continue;
            };
            if ext == "txt" {
                continue;
            }
            let case = label.trim().rsplit(['/', ' ']).next().unwrap_or("unknown");
            let kept = failures.join(format!("{prefix}-{case}-abort.{ext}"));
            if std::fs::rename(entry.path(), &kept).is_ok() {
                saved.push(kept);
            }
        }
    }
    let tail: Vec<&str> = stderr.lines().rev().take(12).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    let aborted = !label.is_empty() && !stderr.contains("test result:");
    if aborted {
        panic!(
            "{test}: the child process died ({}) during {}; input saved as {saved:?}; its last \
             output:\n{}",
            out.status,
            label.trim(),
            tail.join("\n")
        );
    }
    panic!("{test}: failed ({}); see the output above", out.status);
}

/// Runs the seeds, the regressions and the mutated cases of `parser` on a worker thread
/// under a watchdog; panics (fails the test) on any panic, hang or broken promise.
fn check(parser: Parser) {
    let only = std::env::var("CUTLAB_MUTATION_ONLY").ok();
    let only_case: Option<u64> = match only.as_deref().and_then(|o| o.split_once(':')) {
        Some((name, case)) if name == parser.name => Some(
            case.trim()
                .parse()
                .expect("CUTLAB_MUTATION_ONLY=<parser>:<case number>"),
        ),
        Some(_) => {
            eprintln!("{}: skipped (CUTLAB_MUTATION_ONLY={only:?})", parser.name);
            return;
        }
        None => None,
    };
    if let Some(corpus) = std::env::var_os("CUTLAB_WRITE_CORPUS") {
        write_corpus(&parser, Path::new(&corpus));
        return;
    }
    let failures = failures_dir();
    let watchdog_failures = failures.clone();
    let name = parser.name;
    let parts = parser.parts;
    let in_flight = Arc::new(Mutex::new(InFlight::default()));
    let worker_in_flight = in_flight.clone();
    let started = Instant::now();
    let worker = std::thread::Builder::new()
        .name(format!("mutation-{name}"))
        .spawn(move || {
            let parser = parser;
            let mut cases: Vec<(Case, Input)> = Vec::new();
            match only_case {
                Some(n) => cases.push((Case::Mutated(n), mutated_input(&parser, n))),
                None => {
                    for (i, seed) in parser.seeds.iter().enumerate() {
                        cases.push((Case::Seed(i), seed.clone()));
                    }
                    for (label, input) in regressions(parser.name, parser.parts) {
                        cases.push((Case::Regression(label), input));
                    }
                }
            }
            let mutated = if only_case.is_some() {
                0
            } else {
                case_count(&parser)
            };
            let mut counts = Counts::default();
            let mut seed_refusals = Vec::new();
            let listed_count = cases.len();
            let listed = cases.into_iter().map(Some);
            let generated = (0..mutated).map(|_| None);
            for (n, listed) in listed.chain(generated).enumerate() {
                let (case, input) = listed.unwrap_or_else(|| {
                    let case = (n - listed_count) as u64;
                    (Case::Mutated(case), mutated_input(&parser, case))
                });
                if only_case.is_some() {
                    let paths = save(&failures, &format!("{name}-{case}"), parser.parts, &input);
                    eprintln!("{name} case {case}: input saved as {paths:?}");
                }
                // kept on disk while it runs: an abort leaves its reproducer behind
                save(&failures, &format!("{name}-inflight"), parser.parts, &input);
                std::fs::write(
                    failures.join(format!("{name}-inflight.txt")),
                    format!("{name} case {case}\n"),
                )
                .expect("in-flight label");
                {
                    let mut f = worker_in_flight.lock().expect("in-flight lock");
                    f.label = case.to_string();
                    f.input = input.clone();
                    f.started = Some(Instant::now());
                }
                let outcome = catch_unwind(AssertUnwindSafe(|| (parser.run)(&input)));
                worker_in_flight.lock().expect("in-flight lock").started = None;
                counts.cases += 1;
                match outcome {
                    Ok(Ok(())) => counts.ok += 1,
                    Ok(Err(message)) => {
                        counts.err += 1;
                        if let Case::Seed(i) = case {
                            seed_refusals.push(format!("seed {i}: {message}"));
                        }
                    }
                    Err(payload) => {
                        let message = payload
                            .downcast_ref::<String>()
                            .cloned()
                            .or_else(|| payload.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                            .unwrap_or_else(|| "(non-string panic payload)".into());
                        let saved = if counts.panics.len() < 50 {
                            let stem = match &case {
                                Case::Regression(_) => format!("{name}-regression-{n}"),
                                _ => format!("{name}-{case}"),
                            };
                            format!("{:?}", save(&failures, &stem, parser.parts, &input))
                        } else {
                            "(not saved: too many)".into()
                        };
                        counts.panics.push(format!(
                            "{name} case {case}: panicked: {message}; input saved as {saved}"
                        ));
                    }
                }
            }
            for ext in parser.parts {
                let _ = std::fs::remove_file(failures.join(format!("{name}-inflight.{ext}")));
            }
            let _ = std::fs::remove_file(failures.join(format!("{name}-inflight.txt")));
            (counts, seed_refusals)
        })
        .expect("worker thread");

    // the watchdog
    loop {
        if worker.is_finished() {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
        let f = in_flight.lock().expect("in-flight lock");
        if let Some(t) = f.started
            && t.elapsed() > HANG
        {
            let paths = save(
                &watchdog_failures,
                &format!("{name}-hang-{}", f.label.replace(['/', ' '], "_")),
                parts,
                &f.input,
            );
            panic!(
                "{name} case {}: still running after {HANG:?} (a hang); input saved as {paths:?}",
                f.label
            );
        }
    }
    let (counts, seed_refusals) = match worker.join() {
        Ok(r) => r,
        Err(_) => panic!("{name}: the harness itself panicked"),
    };
    let wall = started.elapsed();
    eprintln!(
        "{name}: {} cases in {:.1} s ({:.2} ms each): Ok {}, Err {}, panics {}, hangs 0",
        counts.cases,
        wall.as_secs_f64(),
        wall.as_secs_f64() * 1e3 / counts.cases.max(1) as f64,
        counts.ok,
        counts.err,
        counts.panics.len()
    );
    for p in &counts.panics {
        eprintln!("  {p}");
    }
    assert!(
        counts.panics.is_empty(),
        "{name}: {} of {} cases panicked or broke the parser's promises:\n{}",
        counts.panics.len(),
        counts.cases,
        counts.panics.join("\n")
    );
    assert!(
        only_case.is_some() || seed_refusals.is_empty(),
        "{name}: a seed (valid input) was refused: {seed_refusals:?}"
    );
}

/// Writes the seeds of `parser` as a libFuzzer corpus, `corpus/<parser>/seed-<i>` (several
/// files joined by a NUL byte, as `fuzz/fuzz_targets/mesh_tetgen.rs` splits them).
fn write_corpus(parser: &Parser, corpus: &Path) {
    let dir = corpus.join(parser.name);
    std::fs::create_dir_all(&dir).expect("corpus directory");
    for (i, seed) in parser.seeds.iter().enumerate() {
        std::fs::write(dir.join(format!("seed-{i}")), seed.join(&0u8)).expect("corpus file");
    }
    eprintln!(
        "{}: {} seeds written to {}",
        parser.name,
        parser.seeds.len(),
        dir.display()
    );
}

// ---------------------------------------------------------------------------------------
// Seeds
// ---------------------------------------------------------------------------------------

fn data(path: &str) -> Vec<u8> {
    let path = repo().join("data").join(path);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A small generated box mesh (2 x 2 x 2 cells, 48 tetrahedra) with three regions.
fn small_mesh() -> cutlab_sim::TetMesh {
    let cells = cutlab_sim::generate::GridCells {
        nx: 2,
        ny: 2,
        nz: 2,
    };
    let generated = cutlab_sim::generate::boxed(Point3::origin(), [0.02, 0.01, 0.01], cells)
        .expect("generated box");
    let m = generated.mesh;
    let regions = (0..m.tet_count()).map(|t| (t % 3) as u32).collect();
    cutlab_sim::TetMesh::new(m.positions().to_vec(), m.tets().to_vec(), regions)
        .expect("mesh with regions")
}

/// The small mesh as Gmsh 2.2 (with a `$PhysicalNames` section to skip, points and
/// triangles to skip).
fn gmsh22(mesh: &cutlab_sim::TetMesh) -> String {
    use std::fmt::Write;
    let mut s = String::from(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"tissue\"\n$EndPhysicalNames\n",
    );
    let _ = writeln!(s, "$Nodes\n{}", mesh.vertex_count());
    for (i, p) in mesh.positions().iter().enumerate() {
        let _ = writeln!(s, "{} {} {} {}", i + 1, p.x, p.y, p.z);
    }
    let _ = writeln!(s, "$EndNodes\n$Elements\n{}", mesh.tet_count() + 2);
    let _ = writeln!(s, "1 15 2 0 1 1");
    let _ = writeln!(s, "2 2 2 0 1 1 2 3");
    for (t, (tet, r)) in mesh.tets().iter().zip(mesh.regions()).enumerate() {
        let _ = writeln!(
            s,
            "{} 4 2 {} {} {} {} {} {}",
            t + 3,
            r + 1,
            r + 1,
            tet[0] + 1,
            tet[1] + 1,
            tet[2] + 1,
            tet[3] + 1
        );
    }
    s.push_str("$EndElements\n");
    s
}

/// The small mesh as TetGen files, 1-based, with a point attribute and boundary markers.
fn tetgen_pair(mesh: &cutlab_sim::TetMesh) -> Input {
    use std::fmt::Write;
    let mut node = format!("# generated\n{} 3 1 1\n", mesh.vertex_count());
    for (i, p) in mesh.positions().iter().enumerate() {
        let _ = writeln!(node, "{} {} {} {} 0.5 {}", i + 1, p.x, p.y, p.z, i % 2);
    }
    let mut ele = format!("{} 4 1\n", mesh.tet_count());
    for (t, (tet, r)) in mesh.tets().iter().zip(mesh.regions()).enumerate() {
        let _ = writeln!(
            ele,
            "{} {} {} {} {} {r}",
            t + 1,
            tet[0] + 1,
            tet[1] + 1,
            tet[2] + 1,
            tet[3] + 1
        );
    }
    vec![node.into_bytes(), ele.into_bytes()]
}

/// The small mesh as legacy VTK: classic `CELLS` with point and cell data, or the VTK 5.1
/// `OFFSETS`/`CONNECTIVITY` layout with a `FIELD` region array.
fn legacy_vtk(mesh: &cutlab_sim::TetMesh, vtk51: bool) -> String {
    use std::fmt::Write;
    let n = mesh.tet_count();
    let mut s =
        String::from("# vtk DataFile Version 5.1\ngenerated\nASCII\nDATASET UNSTRUCTURED_GRID\n");
    let _ = writeln!(s, "POINTS {} double", mesh.vertex_count());
    for p in mesh.positions() {
        let _ = writeln!(s, "{} {} {}", p.x, p.y, p.z);
    }
    if vtk51 {
        let _ = writeln!(s, "CELLS {} {}\nOFFSETS vtktypeint64", n + 2, 4 * n + 1);
        let offsets: Vec<String> = (0..=n).map(|c| (4 * c).to_string()).collect();
        let _ = writeln!(s, "{} {}", offsets.join(" "), 4 * n + 1);
        let _ = writeln!(s, "CONNECTIVITY vtktypeint64");
        for tet in mesh.tets() {
            let _ = writeln!(s, "{} {} {} {}", tet[0], tet[1], tet[2], tet[3]);
        }
        let _ = writeln!(s, "0");
        let _ = writeln!(s, "CELL_TYPES {}", n + 1);
        for _ in 0..n {
            s.push_str("10\n");
        }
        s.push_str("1\n");
        let _ = writeln!(s, "CELL_DATA {}\nFIELD FieldData 2", n + 1);
        let _ = writeln!(s, "quality 1 {} double", n + 1);
        for t in 0..=n {
            let _ = write!(s, "{}.25 ", t % 7);
        }
        let _ = writeln!(s, "\nmaterial 1 {} int", n + 1);
        for r in mesh.regions() {
            let _ = write!(s, "{r} ");
        }
        s.push_str("0\nMETADATA\nINFORMATION 0\n\n");
    } else {
        let _ = writeln!(s, "CELLS {} {}", n + 1, 5 * n + 4);
        for tet in mesh.tets() {
            let _ = writeln!(s, "4 {} {} {} {}", tet[0], tet[1], tet[2], tet[3]);
        }
        s.push_str("3 0 1 2\n");
        let _ = writeln!(s, "CELL_TYPES {}", n + 1);
        for _ in 0..n {
            s.push_str("10\n");
        }
        s.push_str("5\n");
        let _ = writeln!(
            s,
            "POINT_DATA {}\nVECTORS velocity double",
            mesh.vertex_count()
        );
        for i in 0..mesh.vertex_count() {
            let _ = writeln!(s, "{i} 0 -1.5e-3");
        }
        let _ = writeln!(
            s,
            "CELL_DATA {}\nSCALARS region int 1\nLOOKUP_TABLE default",
            n + 1
        );
        for r in mesh.regions() {
            let _ = writeln!(s, "{r}");
        }
        s.push_str("0\nLOOKUP_TABLE colours 2\n0 0 0 1\n1 1 1 1\n");
    }
    s
}

/// A trajectory like the expert trainee's: 300 rows at 1 ms, a stroke across the top with
/// the blade engaged in the middle, the tool tilting.
fn trajectory_csv() -> String {
    use std::fmt::Write;
    let mut s = String::from("# generated stroke\nt_s, x_m, y_m, z_m, qw, qx, qy, qz, button\n");
    for i in 0..300 {
        let t = i as f64 * 1e-3;
        let x = -0.03 + 0.0002 * i as f64;
        let z = 0.01 - 0.00005 * i as f64;
        let half = 0.001 * i as f64;
        let button = u8::from((100..250).contains(&i));
        let _ = writeln!(
            s,
            "{t:.3}, {x:.6}, 0.0, {z:.6}, {:.9}, {:.9}, 0, 0, {button}",
            half.cos(),
            half.sin()
        );
        if i == 150 {
            s.push_str("\n# halfway\n");
        }
    }
    s
}

/// OpenIGTLink packets: TRANSFORMs (version 1, and version 2 with an extended header and
/// metadata), a Button STRING and a POINT as the device sends it.
fn igtl_packets() -> Vec<Input> {
    use cutlab_haptics::device::igtl::{self, HEADER_BYTES};
    let rotation = cutlab_haptics::Rotation::from_euler_angles(0.3, -0.2, 1.1);
    let tip = Point3::new(0.012, -0.034, 0.005);
    let mut v1 = Vec::new();
    igtl::encode_transform("Tool", &tip, &rotation, 0x1234_5678_9abc_def0, &mut v1);
    let mut body = vec![0u8; 12];
    body[0..2].copy_from_slice(&12u16.to_be_bytes());
    body[2..4].copy_from_slice(&2u16.to_be_bytes());
    body[4..8].copy_from_slice(&3u32.to_be_bytes());
    body.extend_from_slice(&v1[HEADER_BYTES..]);
    body.extend_from_slice(&[0, 0, b'a', b'b', b'c']);
    let mut v2 = Vec::new();
    igtl::Header::write("TRANSFORM", "Tool", 7, &body, &mut v2);
    v2[1] = 2;
    v2.extend_from_slice(&body);
    let mut button = Vec::new();
    let string_body = [0, 3, 0, 1, b'1'];
    igtl::Header::write("STRING", "Button", 0, &string_body, &mut button);
    button.extend_from_slice(&string_body);
    let mut point = Vec::new();
    igtl::encode_force(&cutlab_sim::Vector3::new(0.5, -1.0, 2.0), 99, &mut point);
    vec![vec![v1], vec![v2], vec![button], vec![point]]
}

/// A real recording: a short session of the expert trainee on the chest wall, made once per
/// test process by the `cutlab` binary.
fn recording() -> &'static [u8] {
    static RECORDING: OnceLock<Vec<u8>> = OnceLock::new();
    RECORDING.get_or_init(|| {
        let dir = scratch("session");
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_cutlab"))
            .args([
                "session",
                "--scene",
                "chest-wall",
                "--min-tets",
                "300",
                "--device",
                "expert",
                "--clock",
                "virtual",
                "--duration",
                "0.3",
                "--seed",
                "1",
                "--out",
            ])
            .arg(&dir)
            .output()
            .expect("run cutlab session");
        assert!(
            out.status.success(),
            "cutlab session failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::fs::read(dir.join("session.mcap")).expect("session.mcap")
    })
}

// ---------------------------------------------------------------------------------------
// One test per parser (libtest runs them on both cores)
// ---------------------------------------------------------------------------------------

fn one(f: fn(&[u8]) -> targets::Outcome) -> Box<dyn Fn(&Input) -> targets::Outcome + Send + Sync> {
    Box::new(move |input: &Input| f(&input[0]))
}

#[test]
fn mesh_vtk_never_panics_on_damaged_input() {
    isolated("mesh_vtk_never_panics_on_damaged_input", || {
        let mesh = small_mesh();
        Parser {
            name: "mesh_vtk",
            parts: &["vtk"],
            text: true,
            seeds: vec![
                vec![legacy_vtk(&mesh, false).into_bytes()],
                vec![legacy_vtk(&mesh, true).into_bytes()],
            ],
            default_cases: 5000,
            run: one(targets::mesh_vtk),
        }
    });
}

#[test]
fn mesh_vtu_never_panics_on_damaged_input() {
    isolated("mesh_vtu_never_panics_on_damaged_input", || {
        let mesh = small_mesh();
        let speed: Vec<f64> = (0..mesh.vertex_count()).map(|i| i as f64 * 0.5).collect();
        let point_data = [("speed", cutlab_sim::io::PointData::Scalar(&speed))];
        let vtu = cutlab_sim::io::vtu_string(&mesh, &point_data).expect("vtu");
        Parser {
            name: "mesh_vtu",
            parts: &["vtu"],
            text: true,
            seeds: vec![vec![vtu.into_bytes()]],
            default_cases: 5000,
            run: one(targets::mesh_vtu),
        }
    });
}

#[test]
fn mesh_gmsh_never_panics_on_damaged_input() {
    isolated("mesh_gmsh_never_panics_on_damaged_input", || Parser {
        name: "mesh_gmsh",
        parts: &["msh"],
        text: true,
        seeds: vec![
            vec![data("ipc/bar-186.msh")],
            vec![data("sofa/liver.msh")],
            vec![gmsh22(&small_mesh()).into_bytes()],
        ],
        default_cases: 5000,
        run: one(targets::mesh_gmsh),
    });
}

#[test]
fn mesh_tetgen_never_panics_on_damaged_input() {
    isolated("mesh_tetgen_never_panics_on_damaged_input", || Parser {
        name: "mesh_tetgen",
        parts: &["node", "ele"],
        text: true,
        seeds: vec![
            vec![data("pbd/armadillo_4k.node"), data("pbd/armadillo_4k.ele")],
            tetgen_pair(&small_mesh()),
        ],
        default_cases: 3000,
        run: Box::new(|input: &Input| targets::mesh_tetgen(&input[0], &input[1])),
    });
}

#[test]
fn nifti_never_panics_on_damaged_input() {
    isolated("nifti_never_panics_on_damaged_input", || {
        use std::io::Read;
        let gz = data("totalsegmentator/example_seg_mr.nii.gz");
        let mut raw = Vec::new();
        flate2::read::GzDecoder::new(&gz[..])
            .read_to_end(&mut raw)
            .expect("gunzip the seed");
        let dir = scratch("nifti");
        Parser {
            name: "nifti",
            parts: &["nii"],
            text: false,
            seeds: vec![vec![gz], vec![raw]],
            default_cases: 2000,
            run: Box::new(move |input: &Input| targets::nifti(&input[0], &dir)),
        }
    });
}

#[test]
fn scene_never_panics_on_damaged_input() {
    isolated("scene_never_panics_on_damaged_input", || {
        let mut seeds = Vec::new();
        for (name, toml) in cutlab_sim::scene::BUILTIN {
            let spec = cutlab_sim::scene::builtin_spec(name).expect("built-in scene");
            let json = serde_json::to_string_pretty(&spec).expect("scene as JSON");
            seeds.push(vec![toml.as_bytes().to_vec()]);
            seeds.push(vec![json.into_bytes()]);
        }
        Parser {
            name: "scene",
            parts: &["scene"],
            text: true,
            seeds,
            default_cases: 5000,
            run: one(targets::scene),
        }
    });
}

#[test]
fn trajectory_csv_never_panics_on_damaged_input() {
    isolated("trajectory_csv_never_panics_on_damaged_input", || Parser {
        name: "trajectory_csv",
        parts: &["csv"],
        text: true,
        seeds: vec![vec![trajectory_csv().into_bytes()]],
        default_cases: 5000,
        run: one(targets::trajectory_csv),
    });
}

#[test]
fn igtl_never_panics_on_damaged_input() {
    isolated("igtl_never_panics_on_damaged_input", || Parser {
        name: "igtl",
        parts: &["bin"],
        text: false,
        seeds: igtl_packets(),
        default_cases: 10000,
        run: one(targets::igtl),
    });
}

/// A page's stream: pointer samples along a line (as `station.js` sends them), a pen's, and
/// Stop, one message per line.
fn station_messages() -> Vec<Input> {
    let mut lines = Vec::new();
    for k in 0..20 {
        let x = -0.03 + 0.003 * f64::from(k);
        lines.push(format!(
            r#"{{"type":"pointer","t_ms":{},"surface_in_world_m":[{x},0.001,0.0151],"depth_m":0.004,"blade_engaged":{}}}"#,
            1000.0 + 16.7 * f64::from(k),
            k > 3
        ));
    }
    lines.push(r#"{"type":"pointer","t_ms":1400.5,"surface_in_world_m":[0.03,0,0.015],"depth_m":0.006,"blade_engaged":true,"pressure":0.5,"world_from_tool_xyzw":[0,0,0,1]}"#.to_owned());
    lines.push(r#"{"type":"stop"}"#.to_owned());
    vec![vec![lines.join("\n").into_bytes()]]
}

#[test]
fn station_ws_never_panics_on_damaged_input() {
    isolated("station_ws_never_panics_on_damaged_input", || Parser {
        name: "station_ws",
        parts: &["txt"],
        text: true,
        seeds: station_messages(),
        default_cases: 10000,
        run: one(station_targets::station_ws),
    });
}

// The recordings: mcap 0.26 reserves a length declared inside a record before reading it, so
// the recorder checks every such length first (recorder/src/scan.rs; the reproducers of a
// Metadata string asking for gigabytes are in tests/fuzz-regressions/mcap_*/).
#[test]
fn mcap_read_never_panics_on_damaged_input() {
    isolated("mcap_read_never_panics_on_damaged_input", || Parser {
        name: "mcap_read",
        parts: &["mcap"],
        text: false,
        seeds: vec![vec![recording().to_vec()]],
        default_cases: 500,
        run: Box::new(|input: &Input| recording_targets::mcap_read(&input[0])),
    });
}

#[test]
fn mcap_recover_never_panics_on_damaged_input() {
    isolated("mcap_recover_never_panics_on_damaged_input", || {
        let dir = scratch("mcap-recover");
        Parser {
            name: "mcap_recover",
            parts: &["mcap"],
            text: false,
            seeds: vec![vec![recording().to_vec()]],
            default_cases: 300,
            run: Box::new(move |input: &Input| recording_targets::mcap_recover(&input[0], &dir)),
        }
    });
}

#[test]
fn the_fuzz_targets_tetgen_input_is_both_files_joined_by_a_nul() {
    let pair = tetgen_pair(&small_mesh());
    assert_eq!(targets::mesh_tetgen_joined(&pair.join(&0u8)), Ok(()));
    assert!(targets::mesh_tetgen_joined(&pair[0]).is_err(), "no .ele");
}

#[test]
fn the_mutator_is_deterministic_and_damages() {
    let seed = b"$Nodes\n3\n1 0.5 -2 3e-3\n2 1 1 1\n$EndNodes\n".to_vec();
    let a: Vec<Vec<u8>> = (0..50)
        .map(|i| mutate(&mut Rng::new(i), &seed, true))
        .collect();
    let b: Vec<Vec<u8>> = (0..50)
        .map(|i| mutate(&mut Rng::new(i), &seed, true))
        .collect();
    assert_eq!(a, b, "the same seed gives the same input");
    assert!(
        a.iter().filter(|m| **m != seed).count() > 40,
        "nearly all differ"
    );
    let mut rng = Rng::new(7);
    let numbers = (0..200)
        .filter_map(|_| find_number(&mut rng, &seed))
        .map(|(s, e)| String::from_utf8_lossy(&seed[s..e]).into_owned())
        .collect::<std::collections::BTreeSet<_>>();
    let expected = ["3", "1", "0.5", "-2", "3e-3", "2"];
    assert!(expected.iter().all(|e| numbers.contains(*e)), "{numbers:?}");
}
