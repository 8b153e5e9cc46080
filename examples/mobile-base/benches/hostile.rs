//! The hostile peer of `tests/hostile.rs`, for longer (`docs/performance.md`,
//! "A hostile peer"): the same seeded fuzz of every key kind against the robot and
//! its station, two processes on loopback, with many more actions; then the counts
//! checked, and the figures printed: actions per kind, what each node counted, the
//! memory of both processes, the robot's CPU and its missed deadlines.
//!
//! ```sh
//! cargo bench -p mobile-base --features network --bench hostile             # 50,000 actions
//! cargo bench -p mobile-base --features network --bench hostile -- --quick  # 10,000
//! ```

#[path = "../tests/fuzz/mod.rs"]
mod fuzz;

use std::time::{Duration, Instant};

use fuzz::{Fuzzer, PATIENCE, Processes, cpu, rss_kib};

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let actions: u64 = if quick { 10_000 } else { 50_000 };
    let mut processes = Processes::start("120min");
    let mut fuzzer = Fuzzer::connect(&processes.endpoints, fuzz::SEED);
    fuzzer.oversized_left = 3;
    let before = fuzz::wait_for("the counts", || fuzzer.counts());
    let rss_before = (rss_kib(&processes.robot), rss_kib(&processes.station));
    let cpu_before = cpu(&processes.robot);
    let missed_before = fuzzer.missed_by_component();
    let load_before = loadavg();
    let started = Instant::now();
    let mut peak = rss_before;
    for n in 1..=actions {
        fuzzer.step();
        if n % 1_000 == 0 {
            processes.drain();
            assert!(processes.alive(), "{}", processes.seen.join("\n"));
            let rss = (rss_kib(&processes.robot), rss_kib(&processes.station));
            peak = (peak.0.max(rss.0), peak.1.max(rss.1));
            if n % 10_000 == 0 {
                println!(
                    "after {n:>6} actions: RSS robot {} KiB, station {} KiB",
                    rss.0, rss.1
                );
            }
        }
    }
    let took = started.elapsed();
    let cpu_robot = cpu(&processes.robot) - cpu_before;
    let expected = fuzzer.expected(&before);
    let mut last = None;
    let deadline = Instant::now() + PATIENCE;
    while last != Some(expected) && Instant::now() < deadline {
        last = fuzzer.counts();
        std::thread::sleep(Duration::from_millis(50));
    }
    let rss_after = (rss_kib(&processes.robot), rss_kib(&processes.station));
    let missed: Vec<(String, u64)> = fuzzer
        .missed_by_component()
        .into_iter()
        .map(|(path, n)| {
            let before = missed_before
                .iter()
                .find(|(p, _)| *p == path)
                .map_or(0, |(_, n)| *n);
            (path, n - before)
        })
        .filter(|(_, n)| *n > 0)
        .collect();
    let figures = &fuzzer.figures;
    println!(
        "{} actions in {took:.1?} (seed {:#x})",
        figures.total(),
        fuzz::SEED
    );
    for (kind, n) in &figures.sent {
        println!("  {kind:<45} {n:>8}");
    }
    println!("counted before   {before:?}");
    println!("counted after    {last:?}");
    println!("expected         {expected:?}");
    println!(
        "refused {} commands and requests; accepted {}; unanswered {}",
        figures.refused,
        figures.accepted.len(),
        figures.unanswered.len()
    );
    println!(
        "RSS robot {} -> {} KiB (peak {}), station {} -> {} KiB (peak {})",
        rss_before.0, rss_after.0, peak.0, rss_before.1, rss_after.1, peak.1
    );
    println!(
        "robot CPU {cpu_robot:.1?} over {took:.1?} ({:.0} %); deadlines missed {missed:?}",
        cpu_robot.as_secs_f64() / took.as_secs_f64() * 100.0
    );
    println!("load average before {load_before}, after {}", loadavg());
    drop(fuzzer);
    let (status, out) = processes.stop_robot();
    let clean = out.contains("clean: every component dead, every thread joined");
    println!("robot exit {status}, shutdown clean: {clean}");
    let station = processes.stop_station();
    println!("station exit {station}");
    assert_eq!(last, Some(expected), "the counts");
    assert!(status.success() && clean, "{out}");
}

/// The first three fields of `/proc/loadavg`.
fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|text| {
            text.split_whitespace()
                .take(3)
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_default()
}
