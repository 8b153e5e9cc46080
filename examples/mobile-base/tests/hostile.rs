//! A hostile peer against the robot and its station, two processes on loopback
//! (`tests/fuzz`): a seeded fuzz of every key kind a node serves. Neither process
//! crashes or stops answering, every bad packet on a bridge is counted at its inlet
//! (one reset per forged jump or far report, nothing counted missing), every bad
//! command and request is refused, both processes' memory stays bounded, and the
//! robot then shuts down cleanly.
#![cfg(feature = "network")]

mod fuzz;

use std::time::{Duration, Instant};

use fuzz::{Fuzzer, PATIENCE, Processes, cpu, rss_kib};

/// Actions of the fuzz: packets, questions, tokens, commands and requests.
const ACTIONS: u64 = 3_000;

#[test]
fn a_hostile_peer_crashes_nothing_and_every_bad_packet_is_counted() {
    let mut processes = Processes::start("10min");
    let mut fuzzer = Fuzzer::connect(&processes.endpoints, fuzz::SEED);
    let before = fuzz::wait_for("the counts", || fuzzer.counts());
    let rss_before = (rss_kib(&processes.robot), rss_kib(&processes.station));
    let cpu_before = cpu(&processes.robot);
    let missed_before = fuzzer.missed_deadlines();
    let started = Instant::now();
    for _ in 0..ACTIONS {
        fuzzer.step();
    }
    let took = started.elapsed();
    processes.drain();
    assert!(processes.alive(), "{}", processes.seen.join("\n"));

    // One generation of the wanderer all along: placed again, its counts would
    // start over under a new name (the lease and silence bounds rule that out).
    let instance = &fuzzer.placement.instance;
    let placed: Vec<String> = fuzzer
        .ctl
        .components(Some("station"))
        .expect("the station lists its components")
        .into_iter()
        .map(|listed| listed.path)
        .filter(|path| !path.starts_with(instance.as_str()))
        .collect();
    assert!(
        placed.is_empty(),
        "the station runs more than `{instance}`: {placed:?}"
    );

    // Every bad packet counted, every forged jump one reset, nothing else.
    let expected = fuzzer.expected(&before);
    let mut last = None;
    let deadline = Instant::now() + PATIENCE;
    while last != Some(expected) && Instant::now() < deadline {
        last = fuzzer.counts();
        std::thread::sleep(Duration::from_millis(50));
    }
    let figures = &fuzzer.figures;
    processes.drain();
    assert_eq!(
        last,
        Some(expected),
        "counted (from {before:?}) against what was sent: {figures:#?}\n{}",
        processes.seen.join("\n")
    );
    // Every bad command and request answered, and refused.
    assert!(figures.accepted.is_empty(), "{:#?}", figures.accepted);
    assert!(figures.unanswered.is_empty(), "{:#?}", figures.unanswered);
    assert!(figures.refused > 0);

    // Both still run, answer, and hold their memory.
    processes.drain();
    assert!(processes.alive(), "{}", processes.seen.join("\n"));
    let rss_after = (rss_kib(&processes.robot), rss_kib(&processes.station));
    let cpu_robot = cpu(&processes.robot) - cpu_before;
    let missed = fuzzer.missed_deadlines() - missed_before;
    eprintln!(
        "{} actions in {took:.1?}: {:#?}\nRSS robot {} -> {} KiB, station {} -> {} KiB; robot CPU {cpu_robot:.1?}; deadlines missed {missed}",
        fuzzer.figures.total(),
        fuzzer.figures.sent,
        rss_before.0,
        rss_after.0,
        rss_before.1,
        rss_after.1,
    );
    for (who, before, after) in [
        ("robot", rss_before.0, rss_after.0),
        ("station", rss_before.1, rss_after.1),
    ] {
        // Generous: an oversized packet passes through each process once.
        assert!(
            after < before * 3 + 256 * 1024,
            "{who}'s memory grew from {before} KiB to {after} KiB"
        );
    }
    fuzzer
        .ctl
        .snapshot("robot/robot")
        .expect("the robot answers");
    fuzzer
        .ctl
        .snapshot(&format!("station/{}", fuzzer.placement.instance))
        .expect("the station answers");

    // The robot shuts down cleanly.
    drop(fuzzer);
    let (status, out) = processes.stop_robot();
    processes.drain();
    assert!(
        status.success(),
        "{status}\n{out}\n{}",
        processes.seen.join("\n")
    );
    assert!(
        out.contains("clean: every component dead, every thread joined"),
        "{out}"
    );
    let status = processes.stop_station();
    assert!(status.success(), "{status}");
}
