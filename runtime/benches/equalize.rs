//! Equalization (paper 3.6, `coolbot::equalize`): two periodic components (20 ms, 6 ms
//! of CPU each) started in phase on one core, with equalization off, then on, in the
//! same process. For each section: its start lateness (deadline to start,
//! `Context::deadline`) and its end lateness (deadline to the end of its 6 ms of CPU:
//! in phase, the scheduler slices the core between the two, so both end late even when
//! both start on time). With equalization on, the figures are split at the moment the
//! `Equalized` step was seen.
//!
//! `cargo bench -p coolbot --bench equalize` (add `-- --quick` for a smoke run).

#[cfg(target_os = "linux")]
#[path = "equalize_common/mod.rs"]
mod equalize_common;

#[cfg(target_os = "linux")]
fn main() {
    use std::time::{Duration, Instant};

    use coolbot::adapt::AdaptAction;
    use coolbot::{MonitorEvent, System};
    use equalize_common::{Starts, pin_to_one_core, spinner};

    let quick = std::env::args().any(|arg| arg == "--quick");
    let run_for = Duration::from_secs(if quick { 2 } else { 6 });
    pin_to_one_core();
    println!(
        "equalization ({} mode): two 20 ms components, 6 ms of CPU each, in phase on CPU 0, {run_for:?} per run",
        if quick { "quick" } else { "full" }
    );
    for equalize in [false, true] {
        let starts = [Starts::default(), Starts::default()];
        let mut system = System::new();
        let a = system.add(spinner("a", &starts[0], equalize)).expect("add");
        let b = system.add(spinner("b", &starts[1], equalize)).expect("add");
        let events = [a.subscribe(), b.subscribe()];
        system.run_all().expect("run");
        let started = Instant::now();
        let mut moved: Option<(Instant, String)> = None;
        while started.elapsed() < run_for {
            for receiver in &events {
                for event in receiver.try_iter() {
                    if let MonitorEvent::Adaptation(step) = event
                        && step.action == AdaptAction::Equalized
                        && moved.is_none()
                    {
                        moved = Some((Instant::now(), step.to_string()));
                    }
                }
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let report = system.shutdown();
        assert!(report.clean(), "{report:?}");
        let sections: Vec<(Instant, Duration, Duration)> = starts
            .iter()
            .flat_map(|s| s.lock().expect("starts").clone())
            .collect();
        let split = moved.as_ref().map_or(Instant::now(), |(at, _)| *at);
        let (before, after): (Vec<&(Instant, Duration, Duration)>, Vec<_>) =
            sections.iter().partition(|(at, _, _)| *at < split);
        println!(
            "  equalization {}: {}",
            if equalize { "on" } else { "off" },
            moved
                .as_ref()
                .map_or("nothing moved".to_owned(), |(_, step)| step.clone())
        );
        for (label, part) in [("before", &before), ("after", &after)] {
            if part.is_empty() {
                continue;
            }
            let start: Vec<Duration> = part.iter().map(|s| s.1).collect();
            let end: Vec<Duration> = part.iter().map(|s| s.2).collect();
            println!(
                "    {label:6} {:4} sections: start lateness p50 {:?} p99 {:?}; end p50 {:?} p99 {:?}",
                part.len(),
                percentile(start.clone(), 0.5),
                percentile(start, 0.99),
                percentile(end.clone(), 0.5),
                percentile(end, 0.99),
            );
        }
    }
}

#[cfg(target_os = "linux")]
fn percentile(mut values: Vec<std::time::Duration>, p: f64) -> std::time::Duration {
    values.sort();
    let index = ((values.len() as f64 - 1.0) * p).round() as usize;
    values.get(index).copied().unwrap_or_default()
}

#[cfg(not(target_os = "linux"))]
fn main() {
    println!("equalization bench: Linux only (it pins threads to one core)");
}
