//! `coolc` on the example descriptions and on a generated description set: check time
//! (`coolc::analyze`: parse, resolve, check) and full compile time, not counting
//! cargo: analyze, lower, and emit (render, format what needs it, write the crate
//! into a new temporary directory: `coolc::merge::write_crate`, what `coolc compile`
//! does); then a recompile with nothing changed (all of it again into the same
//! directory).
//!
//! The generated set has 1,000 atomic and 100 compound components, one file each,
//! plus a shared types file (see [`generate`]). The scaling run does the same with ten
//! times the input (10,000 + 1,000). Goals: the 1,000 set checks and
//! emits in under one second, and ten times the input costs at most twelve times the
//! time. The baseline of the scaling figure is the 1x run of the same path: children
//! of the two sets run in turn, and the figure is the median of the ratios of a 1x
//! child and the 10x child after it ([`PAIRS`]).
//!
//! Every file of these crates comes out of its template in rustfmt's layout (what
//! coolc's layout is not certain of would go to the `rustfmt` program when it is
//! installed, else to `prettyplease`: nothing here). The `Builder` (build scripts)
//! writes one unformatted file by default. All three paths are measured, each in a
//! child process of this benchmark (`RUSTFMT` names a missing program for the
//! `Builtin` and `Unformatted` rows).
//!
//! The crates are written into a temporary directory under [`scratch_root`]: cargo's
//! `CARGO_TARGET_TMPDIR` on the disk, as a user's crate is, unless `COOLC_BENCH_DIR`
//! names another (`/dev/shm` measures coolc without the disk: see there).
//!
//! `cargo bench -p coolc --bench compile` (add `-- --quick` to skip the 10x runs).
//! `--write-set SET DIR` writes a set's descriptions into DIR, to time the `coolc`
//! binary itself.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// In-memory description files.
type Files = BTreeMap<PathBuf, String>;

/// Shared packets and enums of the generated set.
const TYPES: &str = r#"/// Pose of the platform in the odometry frame.
packet Pose2D { x: f64, y: f64, theta: f64 }

/// A velocity command.
packet Twist { linear: f64, angular: f64 }

/// One reading of a ring of range sensors.
packet RangeScan { stamp: Time, ranges: [f32; 16], bumpers: [bool; 8] = [false; 8] }

/// Operating modes.
enum Mode { Normal, Degraded, Stopped }
"#;

fn atomic_name(index: usize) -> String {
    format!("Worker{index:05}")
}

fn atomic_file(index: usize) -> String {
    format!("atomic_{index:05}.cool")
}

/// A realistically sized atomic component: configuration, variables of every kind,
/// six ports of five kinds, timing, three exceptions with plans and a four-state
/// automaton with entry, exit and periodic sections, `on`, `after`, a watchdog and
/// `may` transitions.
fn atomic(index: usize) -> String {
    let name = atomic_name(index);
    format!(
        r#"import "types.cool";

/// Generated worker number {index}: follows commands and reports its pose.
atomic {name} {{
    configuration {{
        device: String = "/dev/ttyUSB{port}";
        max_speed: f64 = 0.8;
        retries: u32 = 3;
    }}

    observable odometry: Pose2D;
    observable battery: f32 = 12.0;
    controllable max_speed: f64 = 0.8;
    local last_command: Time?;
    local count: u64 = 0;

    input command: fifo<Twist>(16);
    input scan: last<RangeScan>;
    input target: last<Pose2D>;
    input halt: tick;
    output command_out: data<Twist>;
    output pose: data<Pose2D>;
    output alarm: tick;

    timing {{
        period 10ms..40ms;
        max_response 20ms;
        priority {priority};
        quality full, reduced;
    }}

    exception link_lost "link lost" {{ retry 3 every 100ms; }}
    exception stalled {{ goto stopped; }}
    exception overheated;

    automaton {{
        initial idle;
        state idle {{
            entry;
            on command -> moving;
        }}
        state moving {{
            entry; periodic; exit;
            on halt -> stopped;
            after 500ms without command -> idle;
            may -> idle, stopped;
        }}
        state stopped {{ entry; after 2s -> recovering; }}
        state recovering {{
            entry; periodic 20ms;
            may -> idle;
        }}
    }}
}}
"#,
        port = index % 8,
        priority = index % 10,
    )
}

fn compound_file(index: usize) -> String {
    format!("compound_{index:04}.cool")
}

/// A compound of 5 to 10 instances of generated atomics, chained by fifo, last and
/// tick connections, with exported ports, mapped and own variables, error policies,
/// a recovery block and a three-state supervisor with rules.
fn compound(index: usize, atomics: usize) -> String {
    let size = 5 + index % 6;
    let members: Vec<usize> = (0..size).map(|k| (index * 10 + k) % atomics).collect();
    let mut text = String::new();
    text.push_str("import \"types.cool\";\n");
    let mut imported = std::collections::BTreeSet::new();
    for &member in &members {
        if imported.insert(member) {
            let _ = writeln!(text, "import \"{}\";", atomic_file(member));
        }
    }
    let _ = writeln!(
        text,
        "\n/// Generated assembly number {index}.\ncompound Assembly{index:04} {{"
    );
    for (k, &member) in members.iter().enumerate() {
        if k == 0 {
            let _ = writeln!(
                text,
                "    instance w{k}: {} {{\n        max_speed = 0.5;\n        timing {{ priority 7; period 20ms..50ms; }}\n    }}",
                atomic_name(member)
            );
        } else {
            let _ = writeln!(text, "    instance w{k}: {};", atomic_name(member));
        }
    }
    text.push('\n');
    for k in 0..size - 1 {
        let next = k + 1;
        let _ = writeln!(text, "    connect w{k}.command_out -> w{next}.command;");
        let _ = writeln!(text, "    connect w{k}.pose -> w{next}.target;");
        let _ = writeln!(text, "    connect w{k}.alarm -> w{next}.halt;");
    }
    let last = size - 1;
    let _ = write!(
        text,
        r#"
    input command = w0.command;
    output pose = w{last}.pose;
    observable odometry = w0.odometry;
    controllable max_speed = w0.max_speed;
    observable mode: Mode = Mode::Normal;
    local faults: u32 = 0;

    on error w0: propagate;
    on error w1: restart;
    recovery {{ retry every 500ms; deadline 5s; }}

    supervisor {{
        initial operating;
        state operating {{
            entry;
            when w1.state == running_error -> degraded;
            when w0.result == fail || faults > 3 -> stopped;
        }}
        state degraded {{
            entry;
            when w1.state == running && w1.user_state == moving -> operating;
        }}
        state stopped {{ entry; }}
    }}
}}
"#
    );
    text
}

/// The generated set: `atomics` atomic and `compounds` compound components.
fn generate(atomics: usize, compounds: usize) -> Files {
    let mut files = Files::new();
    files.insert(PathBuf::from("types.cool"), TYPES.to_owned());
    for index in 0..atomics {
        files.insert(PathBuf::from(atomic_file(index)), atomic(index));
    }
    for index in 0..compounds {
        files.insert(
            PathBuf::from(compound_file(index)),
            compound(index, atomics),
        );
    }
    files
}

/// The `.cool` files under `dir` (relative to the workspace root), recursively.
fn descriptions(dir: &str) -> Files {
    // coolc normalises import paths lexically: give it a path without `..`.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .join(dir);
    let mut files = Files::new();
    let mut dirs = vec![root];
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() && !path.ends_with("target") {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "cool")
                && let Ok(text) = std::fs::read_to_string(&path)
            {
                files.insert(path, text);
            }
        }
    }
    files
}

fn loader(files: &Files) -> impl Fn(&Path) -> std::io::Result<String> + '_ {
    move |path: &Path| {
        files
            .get(path)
            .cloned()
            .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
    }
}

/// Wall-clock and CPU time (this process, all threads; not child processes) of one
/// stage.
#[derive(Debug, Clone, Copy, Default)]
struct Cost {
    wall: Duration,
    cpu: Duration,
}

impl std::ops::Add for Cost {
    type Output = Cost;
    fn add(self, other: Cost) -> Cost {
        Cost {
            wall: self.wall + other.wall,
            cpu: self.cpu + other.cpu,
        }
    }
}

impl std::iter::Sum for Cost {
    fn sum<I: Iterator<Item = Cost>>(iter: I) -> Cost {
        iter.fold(Cost::default(), |a, b| a + b)
    }
}

fn measure<R>(f: impl FnOnce() -> R) -> (Cost, R) {
    let cpu = cpu_time::ProcessTime::now();
    let wall = Instant::now();
    let result = f();
    let cost = Cost {
        wall: wall.elapsed(),
        cpu: cpu.elapsed(),
    };
    (cost, result)
}

/// The times of one run over a set.
#[derive(Debug, Clone, Copy)]
struct Times {
    check: Cost,
    lower: Cost,
    /// Render, format and write the crate into a new directory (`coolc compile`), or
    /// render and write the single file (`Builder`).
    emit: Cost,
    /// The whole compile again into the same directory: check, lower, emit.
    recompile: Cost,
    files: usize,
    bytes: usize,
}

impl Times {
    fn compile(self) -> Cost {
        self.check + self.lower + self.emit
    }
}

/// Check, lower and emit `roots` as `coolc compile` does (the crate written into a
/// new temporary directory: [`coolc::merge::write_crate`]), then all of it again into
/// the same directory (a recompile with nothing changed); for
/// [`Formatter::Unformatted`] the single unformatted file the `Builder` writes into
/// `OUT_DIR`.
fn run(files: &Files, roots: &[PathBuf], formatter: Formatter) -> Times {
    let load = loader(files);
    // Kept until the whole benchmark ends (the parent removes its directory): ext4
    // avoids reusing inodes deleted in the last minutes, scanning for free ones, so
    // deleting 2,000 or 20,000 files before the next row would slow that row's file
    // creation.
    let dir = tempfile::tempdir().expect("temporary directory").keep();
    let once = || {
        let (check, analysis) = measure(|| coolc::analyze(roots, &load));
        let checked = analysis.checked().unwrap_or_else(|analysis| {
            panic!(
                "the benchmark's descriptions must be valid:\n{}",
                analysis.render(coolc::RenderOptions::plain())
            )
        });
        let options = coolc::lower::Options::default();
        let (lower, krate) = measure(|| coolc::lower::lower(&checked, &options));
        let (emit, (files, bytes)) = measure(|| {
            if formatter == Formatter::Unformatted {
                // As the `Builder` writes it.
                let path = dir.join("cool.rs");
                let file = std::fs::File::create(&path).expect("create the file");
                coolc::emit::write_single_file_with(
                    &krate,
                    coolc::emit::Formatting::Unformatted,
                    &mut std::io::BufWriter::new(file),
                )
                .expect("write the file");
                let len = std::fs::metadata(&path).expect("the file").len();
                (1, len as usize)
            } else {
                coolc::merge::write_crate(&dir, &krate).expect("write the crate");
                crate_size(&dir)
            }
        });
        (check, lower, emit, files, bytes)
    };
    let (check, lower, emit, files, bytes) = once();
    let (check2, lower2, emit2, _, _) = once();
    Times {
        check,
        lower,
        emit,
        recompile: check2 + lower2 + emit2,
        files,
        bytes,
    }
}

/// Files and bytes of the crate in `dir` (`src/` and `Cargo.toml`).
fn crate_size(dir: &Path) -> (usize, usize) {
    let mut files = 0;
    let mut bytes = 0;
    let mut dirs = vec![dir.join("src")];
    if let Ok(meta) = std::fs::metadata(dir.join("Cargo.toml")) {
        files += 1;
        bytes += meta.len() as usize;
    }
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                dirs.push(path);
            } else if let Ok(meta) = entry.metadata() {
                files += 1;
                bytes += meta.len() as usize;
            }
        }
    }
    (files, bytes)
}

/// Rounds of the 1x and the 10x generated sets in each child of a full run, each
/// child's figure the median by compile time. The same number for both sets: a
/// process's first round grows its heap (page faults, memory the kernel zeroes) and
/// the later ones reuse it, so a child of one round is slower per input than the
/// median of several, and the ratio must compare like with like. A single round of
/// the 1x set (under a second) moved by a third from run to run on this machine, and
/// the 10x ratio with it (8x to 18x) while the work scaled by 10 (the samples of a
/// `perf record` of both children: 8.97x). Every round writes into a directory of its
/// own, kept until the benchmark ends (see [`run`]), so no round follows a deletion.
const SET_ROUNDS: (usize, usize) = (3, 3);

/// Children of the 1x and the 10x set run in turn on each path in a full run (1x,
/// 10x, 1x, 10x, ...). The ratio is the median of the pairs' ratios, each of two
/// children run one after the other: the machine's speed drifts by a fifth within
/// minutes on this shared virtual machine (the check stage alone, which touches no
/// disk, took 2.5 s in one run of the 10x set and 3.1 s in the next), and a 1x row
/// measured a minute away from its 10x row carried that drift into the ratio.
const PAIRS: usize = 3;

/// The median of `times` by compile time (wall).
fn median_times(mut times: Vec<Times>) -> Times {
    times.sort_by_key(|t| t.compile().wall);
    times[times.len() / 2]
}

/// The median run of `rounds` by compile time.
fn median_run(rounds: usize, files: &Files, roots: &[PathBuf], formatter: Formatter) -> Times {
    median_times((0..rounds).map(|_| run(files, roots, formatter)).collect())
}

fn ms(d: Duration) -> String {
    format!("{:.1} ms", d.as_secs_f64() * 1e3)
}

fn cost(c: Cost) -> String {
    format!("{} (cpu {})", ms(c.wall), ms(c.cpu))
}

/// The input sets, by name.
fn input(set: &str) -> Files {
    match set {
        "examples" => descriptions("examples"),
        "fixtures" => descriptions("tests/data/ok"),
        "slice" => generate(10, 1),
        "1x" => generate(1_000, 100),
        "10x" => generate(10_000, 1_000),
        other => panic!("unknown set {other}"),
    }
}

/// Child mode: `--child SET ROUNDS FORMATTER`; prints `check lower emit recompile
/// files bytes` (seconds, counts) of the median round.
fn child(set: &str, rounds: usize, formatter: Formatter) {
    let files = input(set);
    let roots: Vec<PathBuf> = files.keys().cloned().collect();
    let t = if set == "fixtures" {
        // Each fixture is a description set of its own: compile them one by one.
        let runs: Vec<Times> = roots
            .iter()
            .map(|root| median_run(rounds, &files, std::slice::from_ref(root), formatter))
            .collect();
        Times {
            check: runs.iter().map(|t| t.check).sum(),
            lower: runs.iter().map(|t| t.lower).sum(),
            emit: runs.iter().map(|t| t.emit).sum(),
            recompile: runs.iter().map(|t| t.recompile).sum(),
            files: runs.iter().map(|t| t.files).sum(),
            bytes: runs.iter().map(|t| t.bytes).sum(),
        }
    } else {
        median_run(rounds, &files, &roots, formatter)
    };
    let mut line = String::new();
    for c in [t.check, t.lower, t.emit, t.recompile] {
        let _ = write!(line, "{} {} ", c.wall.as_secs_f64(), c.cpu.as_secs_f64());
    }
    println!("{line}{} {}", t.files, t.bytes);
}

/// How generated code is formatted in a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Formatter {
    /// As shipped when `rustfmt` is installed: the files not emitted in rustfmt's
    /// layout (none in the generated sets) are formatted by one `rustfmt` run.
    Rustfmt,
    /// `RUSTFMT` names a program that does not exist, so coolc formats with its
    /// built-in fallback (`prettyplease`, in process).
    Builtin,
    /// The `Builder` path: one unformatted file (`Builder` default), no user files.
    Unformatted,
}

impl Formatter {
    fn parse(name: &str) -> Formatter {
        match name {
            "Rustfmt" => Formatter::Rustfmt,
            "Builtin" => Formatter::Builtin,
            "Unformatted" => Formatter::Unformatted,
            other => panic!("unknown formatter {other}"),
        }
    }
}

/// Where the benchmark writes its crates: `COOLC_BENCH_DIR` when it is set, else
/// cargo's `CARGO_TARGET_TMPDIR`, on the disk as a user's crate is.
///
/// A disk measures more than coolc: on an ext4 file system without a journal (this
/// project's development machine), creating a file skips every inode freed in the
/// last minutes of its group, reading each one's inode table block, so a compile
/// that creates its 3,306 files (crate, user files and `.coolc/stubs/`) shortly after
/// the deletion of many files (the previous run of this benchmark removes about
/// 650,000, about 10 GiB: every round's crate is kept until the end) spends 0.1 to
/// 0.9 ms of kernel time on each. The benchmark leaves out what it can of its own: it
/// waits until six minutes have passed since its last run removed its files
/// ([`INODE_RECENCY`]), and writes out what is pending on the file system before each
/// child ([`settle`]), so that no child times the write-back of those before.
/// Deletions by other programs in the minutes before remain in the figures.
/// `COOLC_BENCH_DIR=/dev/shm` (a tmpfs) leaves the disk out, and takes those 10 GiB
/// of memory.
fn scratch_root() -> PathBuf {
    if let Some(dir) = std::env::var_os("COOLC_BENCH_DIR") {
        return PathBuf::from(dir);
    }
    PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
}

/// The benchmark's own scratch directory under [`scratch_root`], removed at the end
/// of [`main`] (see [`run`]).
fn scratch() -> &'static Path {
    static SCRATCH: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    SCRATCH
        .get_or_init(|| {
            tempfile::TempDir::with_prefix_in("coolc-bench-", scratch_root())
                .expect("scratch directory")
        })
        .path()
}

/// Writes out what the file system holding the scratch directory has pending
/// (`sync -f`, outside every timed span): the crates of the rows before, which the
/// kernel would otherwise write back (allocating their blocks) 30 s later, during a
/// later row.
fn settle(dir: &Path) {
    let _ = std::process::Command::new("sync")
        .arg("-f")
        .arg(dir)
        .status();
}

/// When this benchmark last removed its scratch directory (a file under
/// [`scratch_root`]).
fn removed_stamp() -> PathBuf {
    scratch_root().join(".coolc-bench-removed")
}

/// How long ext4 without a journal skips the inodes freed by a deletion: one minute
/// after the deletion (`RECENTCY_MIN` in the kernel), five more while their inode
/// table block is dirty, which creating files next to them makes it again. The next
/// run of this benchmark waits that long after the last one removed its files, so
/// that it does not time the allocator stepping over them (measured: right after the
/// removal, `recently_deleted` and its block look-ups take a third of a 1,000 set
/// compile's samples, and the other thread spins on the directory's lock).
const INODE_RECENCY: Duration = Duration::from_secs(361);

/// Waits until [`INODE_RECENCY`] has passed since the last run removed its scratch
/// directory (no wait on a first run); how long it waited.
fn wait_for_last_removal() -> Duration {
    let since = std::fs::metadata(removed_stamp())
        .and_then(|meta| meta.modified())
        .ok()
        .and_then(|at| at.elapsed().ok());
    let wait = since.map_or(Duration::ZERO, |since| INODE_RECENCY.saturating_sub(since));
    std::thread::sleep(wait);
    wait
}

/// Run one set in a child process (the formatter is chosen through the `RUSTFMT`
/// environment variable, which a process cannot safely change for itself).
fn in_child(set: &str, rounds: usize, formatter: Formatter) -> Times {
    settle(scratch());
    let exe = std::env::current_exe().expect("current exe");
    let mut command = std::process::Command::new(exe);
    command.args([
        "--child",
        set,
        &rounds.to_string(),
        &format!("{formatter:?}"),
    ]);
    if formatter != Formatter::Rustfmt {
        command.env("RUSTFMT", "/nonexistent/coolc-bench-no-rustfmt");
    }
    // Output and formatter scratch files go under the scratch directory (see
    // `scratch_root`).
    command.env("TMPDIR", scratch());
    let output = command.output().expect("run the child");
    assert!(
        output.status.success(),
        "child {set} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = String::from_utf8_lossy(&output.stdout);
    let n: Vec<f64> = text
        .split_whitespace()
        .map(|x| x.parse().expect("child output"))
        .collect();
    let [cw, cc, lw, lc, ew, ec, ww, wc, files, bytes] = n[..] else {
        panic!("child {set} printed {text:?}");
    };
    let c = |wall: f64, cpu: f64| Cost {
        wall: Duration::from_secs_f64(wall),
        cpu: Duration::from_secs_f64(cpu),
    };
    Times {
        check: c(cw, cc),
        lower: c(lw, lc),
        emit: c(ew, ec),
        recompile: c(ww, wc),
        files: files as usize,
        bytes: bytes as usize,
    }
}

fn row(name: &str, set: &str, formatter: Formatter, t: Times) {
    let input = input(set);
    let lines: usize = input.values().map(|text| text.lines().count()).sum();
    println!(
        "| {name} | {} files, {lines} lines | {formatter:?} | {} | {} | {} | {} | {} | {} files, {:.1} MiB |",
        input.len(),
        cost(t.check),
        cost(t.lower),
        cost(t.emit),
        cost(t.compile()),
        cost(t.recompile),
        t.files,
        t.bytes as f64 / (1024.0 * 1024.0)
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(at) = args.iter().position(|a| a == "--check-only") {
        // For profiling the front end: `--check-only SET`.
        let files = input(&args[at + 1]);
        let roots: Vec<PathBuf> = files.keys().cloned().collect();
        let (took, analysis) = {
            let started = Instant::now();
            let analysis = coolc::analyze(&roots, &loader(&files));
            (started.elapsed(), analysis)
        };
        println!(
            "check {} ({} diagnostics)",
            ms(took),
            analysis.diagnostics.len()
        );
        return;
    }
    if let Some(at) = args.iter().position(|a| a == "--write-set") {
        // For profiling `coolc compile` itself: `--write-set SET DIR` writes the
        // description files of a set into DIR.
        let dir = Path::new(&args[at + 2]);
        for (path, text) in input(&args[at + 1]) {
            let path = dir.join(path.file_name().expect("a file name"));
            std::fs::create_dir_all(dir).expect("create the directory");
            std::fs::write(path, text).expect("write a description");
        }
        return;
    }
    if let Some(at) = args.iter().position(|a| a == "--child") {
        child(
            &args[at + 1],
            args[at + 2].parse().expect("rounds"),
            Formatter::parse(&args[at + 3]),
        );
        return;
    }
    let quick = args.iter().any(|a| a == "--quick")
        || std::env::var("COOLBOT_BENCH_QUICK").is_ok_and(|v| !v.is_empty() && v != "0");
    let rounds = if quick { 1 } else { 3 };
    let (small_rounds, large_rounds) = if quick { (1, 0) } else { SET_ROUNDS };
    let waited = wait_for_last_removal();
    let large = if quick {
        "no 10x rows".to_owned()
    } else {
        format!(
            "{PAIRS} children of the 1x set ({small_rounds} rounds each) and of the 10x set ({large_rounds} each) in turn, each row the median child"
        )
    };
    println!(
        "### coolc: check and compile times ({} run, median of {rounds} per example row; {large}; crates written under {})\n",
        if quick { "quick" } else { "full" },
        scratch_root().display()
    );
    if !waited.is_zero() {
        println!(
            "(waited {:.0} s for the last run's deletion to age: see `INODE_RECENCY`)\n",
            waited.as_secs_f64()
        );
    }
    println!(
        "| input | size | path | check (analyze) | lower | emit: render, format, write | first compile (check + lower + emit) | recompile, nothing changed | output |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");

    for (set, name) in [
        ("examples", "examples/ (one crate)"),
        ("fixtures", "tests/data/ok (one crate each)"),
    ] {
        if input(set).is_empty() {
            println!("| {name} | none found | | | | | | | |");
            continue;
        }
        for formatter in [Formatter::Rustfmt, Formatter::Builtin] {
            let t = in_child(set, rounds, formatter);
            row(name, set, formatter, t);
        }
    }
    // The 1,000 set on each path: `coolc compile` with rustfmt (the shipped path when
    // rustfmt is installed), with the built-in formatter, and the `Builder`
    // (unformatted); the 10x set on each path in full runs, its children in turn with
    // the 1x set's (`PAIRS`).
    let mut results = Vec::new();
    for formatter in [
        Formatter::Rustfmt,
        Formatter::Builtin,
        Formatter::Unformatted,
    ] {
        let mut pairs = Vec::new();
        for _ in 0..if quick { 1 } else { PAIRS } {
            let small = in_child("1x", small_rounds, formatter);
            let large = (!quick).then(|| in_child("10x", large_rounds, formatter));
            pairs.push((small, large));
        }
        let small = median_times(pairs.iter().map(|&(small, _)| small).collect());
        row("1,000 atomic + 100 compound", "1x", formatter, small);
        let larges: Vec<Times> = pairs.iter().filter_map(|&(_, large)| large).collect();
        let large = (!larges.is_empty()).then(|| {
            let t = median_times(larges);
            row("10,000 atomic + 1,000 compound", "10x", formatter, t);
            t
        });
        results.push((formatter, small, large, pairs));
    }

    println!();
    let verdict = |ok: bool| if ok { "pass" } else { "MISS" };
    let second = Duration::from_secs(1);
    for (formatter, small, large, pairs) in results {
        for (what, c) in [
            ("first compile (check + lower + emit)", small.compile()),
            ("recompile", small.recompile),
            ("check alone", small.check),
        ] {
            println!(
                "- {formatter:?}: 1,000 set, {what}: {} (goal < 1 s): wall {}, cpu {}",
                cost(c),
                verdict(c.wall < second),
                verdict(c.cpu < second)
            );
        }
        let Some(large) = large else {
            continue;
        };
        let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64();
        for (what, pick) in [
            ("wall", (|c: Cost| c.wall) as fn(Cost) -> Duration),
            ("cpu", |c: Cost| c.cpu),
        ] {
            let mut each: Vec<f64> = pairs
                .iter()
                .filter_map(|(small, large)| {
                    large.map(|large| ratio(pick(large.compile()), pick(small.compile())))
                })
                .collect();
            each.sort_by(f64::total_cmp);
            let scaling = each[each.len() / 2];
            let each: Vec<String> = each.iter().map(|r| format!("{r:.2}x")).collect();
            println!(
                "- {formatter:?}, {what}: 10x input costs {scaling:.2}x the time of the first compile (goal <= 12x): {} (median of the pairs' ratios: {}; of the rows' medians: {:.2}x)",
                verdict(scaling <= 12.0),
                each.join(", "),
                ratio(pick(large.compile()), pick(small.compile()))
            );
            println!(
                "- {formatter:?}, {what}: 10x input, per stage (the rows' medians): check {:.2}x, lower {:.2}x, emit {:.2}x, recompile {:.2}x",
                ratio(pick(large.check), pick(small.check)),
                ratio(pick(large.lower), pick(small.lower)),
                ratio(pick(large.emit), pick(small.emit)),
                ratio(pick(large.recompile), pick(small.recompile)),
            );
        }
    }
    if quick {
        println!("- quick run: the 10x set was skipped");
    }
    let _ = std::fs::remove_dir_all(scratch());
    let _ = std::fs::write(removed_stamp(), b"");
}
