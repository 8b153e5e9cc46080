//! The cost of adaptation: the CPU time per period of a 1 kHz component whose
//! adaptation is on (its detector fed every period, a period interval of 1 to 4 ms)
//! against the same component with adaptation off, both running at the same time in
//! alternating rounds; and the cost of one supervisor decision (`adapt::decide`) over
//! 10 and 100 instances; and the idle probe's own CPU share over the rounds
//! (`coolbot::idle`).
//!
//! `cargo bench -p coolbot --bench adapt` (add `-- --quick` for a smoke run).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use coolbot::adapt::{Decision, Levels, Member, ProtectPriority, Reconfiguration, decide};
use coolbot::{
    AdaptConfig, Automaton, Command, Component, Context, Controllable, PortSet, Pressure, Section,
    SectionResult, Spec, State, StateSpec, System, TimingSpec,
};

static TICKER: Spec = Spec::new("Ticker", "")
    .with_states(&[StateSpec::new("ticking").with_periodic(None)])
    .with_timing(TimingSpec {
        period: Some(Duration::from_millis(1)),
        max_period: Some(Duration::from_millis(4)),
        max_response: None,
        priority: 0,
        qualities: &["full", "reduced"],
    });

struct Ticker(Arc<AtomicU64>);

impl Automaton for Ticker {
    fn spec(&self) -> &'static Spec {
        &TICKER
    }
    fn section(&mut self, _state: usize, _section: Section, _cx: &mut Context) -> SectionResult {
        self.0.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }
}

/// CPU time per period (ns) of each component over `rounds` rounds of `each` long:
/// adaptation on, off, and off again (the noise floor of the comparison); and the
/// adapted component's level at the end and adaptation steps taken (on a loaded
/// machine it may be degraded to a longer period, which changes its cost per period).
fn periods(rounds: usize, each: Duration) -> ([Vec<f64>; 3], (u32, u64)) {
    let mut system = System::new();
    let configs = [
        // Never spare, never violating on an idle machine: the detector runs and
        // stays at level 0, which is the steady-state cost.
        AdaptConfig {
            spare_ratio: 0.0,
            ..AdaptConfig::on()
        },
        AdaptConfig::off(),
        AdaptConfig::off(),
    ];
    let sides: Vec<_> = configs
        .iter()
        .enumerate()
        .map(|(index, config)| {
            let count = Arc::new(AtomicU64::new(0));
            let component = Component::new(
                format!("c{index}"),
                Box::new(Ticker(Arc::clone(&count))),
                PortSet::new(),
            )
            .with_adaptation(*config);
            (system.add(component).expect("add"), count)
        })
        .collect();
    system.start().expect("start");
    let mut samples = [Vec::new(), Vec::new(), Vec::new()];
    for round in 0..rounds {
        // Rotate which one starts first.
        let order: Vec<usize> = (0..3).map(|k| (k + round) % 3).collect();
        let before: Vec<_> = sides
            .iter()
            .map(|(h, c)| (h.snapshot().cpu_time, c.load(Ordering::Relaxed)))
            .collect();
        for &index in &order {
            sides[index]
                .0
                .command(Command::SetState(Controllable::Running))
                .expect("running");
        }
        std::thread::sleep(each);
        for &index in &order {
            let handle = &sides[index].0;
            handle
                .command(Command::SetState(Controllable::Ready))
                .expect("ready");
            handle
                .wait_state(State::Ready, Duration::from_secs(5))
                .expect("ready");
        }
        for (index, ((handle, count), (cpu, runs))) in sides.iter().zip(before).enumerate() {
            let cpu = handle.snapshot().cpu_time.saturating_sub(cpu);
            let runs = count.load(Ordering::Relaxed) - runs;
            samples[index].push(cpu.as_nanos() as f64 / runs.max(1) as f64);
        }
    }
    let adapted = sides[0].0.snapshot().adaptation;
    let report = system.shutdown();
    assert!(report.clean(), "{report:?}");
    (samples, (adapted.level, adapted.steps))
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    values[values.len() / 2]
}

fn members(count: usize) -> Vec<Member> {
    (0..count)
        .map(|i| Member {
            name: format!("m{i}"),
            priority: (i % 7) as i32,
            level: (i % 3) as u32,
            max_level: 4,
            min_level: 0,
            pressure: if i == count / 2 {
                Pressure::Violation
            } else {
                Pressure::Nominal
            },
            load: (i % 10) as f64 / 10.0,
            cpu_share: 0.0,
            period: Some(Duration::from_millis(10 + i as u64)),
            suspended: false,
        })
        .collect()
}

fn main() {
    let quick = std::env::args().any(|arg| arg == "--quick");
    let (rounds, each) = if quick {
        (4, Duration::from_millis(250))
    } else {
        (20, Duration::from_millis(500))
    };
    // The idle probe runs while some component adapts: hold a handle on it over the
    // rounds to read its own CPU time against the wall-clock time.
    let probe = coolbot::idle::IdleProbe::shared();
    let probe_started = (Instant::now(), probe.as_ref().map(|p| p.cpu_time()));
    let (samples, (level, steps)) = periods(rounds, each);
    let [on, off, control] = samples.map(median);
    let probe_wall = probe_started.0.elapsed();
    println!(
        "adaptation cost ({} mode)",
        if quick { "quick" } else { "full" }
    );
    println!(
        "  CPU time per 1 kHz period, median of {rounds} rounds: adaptation on {on:.0} ns, off {off:.0} ns, ratio {:.2} (off against off: {:.2})",
        on / off,
        control / off
    );
    println!("  the adapted component ended at level {level} after {steps} adaptation steps");
    match (probe, probe_started.1) {
        (Some(probe), Some(cpu_before)) => {
            let cpu = probe.cpu_time().saturating_sub(cpu_before);
            let (wakes, late) = probe.wakes();
            println!(
                "  idle probe: {:.4}% of a core over {probe_wall:.1?} ({cpu:?} CPU, {wakes} wake-ups, {late} late; idle share {:.2})",
                100.0 * cpu.as_secs_f64() / probe_wall.as_secs_f64(),
                probe.share().unwrap_or(f64::NAN),
            );
        }
        _ => println!("  idle probe: could not start"),
    }
    for count in [10usize, 100] {
        let members = members(count);
        let levels = Levels {
            cap: 2,
            floor: 1,
            top: true,
            reconfiguration: Reconfiguration::Report,
            settled: true,
        };
        let iterations = if quick { 10_000 } else { 100_000 };
        let started = Instant::now();
        let mut degrades = 0usize;
        for _ in 0..iterations {
            if let Decision::Degrade(_) =
                decide(std::hint::black_box(&members), levels, &ProtectPriority)
            {
                degrades += 1;
            }
        }
        let per = started.elapsed() / iterations;
        assert_eq!(degrades, iterations as usize);
        println!("  decide over {count} instances: {per:?} per decision");
    }
}
