//! A component's own adaptation (paper 3.6): its ladder, detector and level.

use super::*;

/// A component's own adaptation: its ladder, its detector and where it stands.
pub(super) struct Local {
    /// Whether detection runs (`AdaptConfig::enabled_for`).
    pub(super) enabled: bool,
    pub(super) ladder: Ladder,
    pub(super) detector: Detector,
    /// Where the component stands: [`Ladder::level_of`] its period and quality.
    pub(super) level: u32,
    /// What was set by other means (a command, a `degrade` plan step, the component's
    /// own `set_period`): promotions stop there.
    pub(super) floor: Floor,
    /// `set_level` is applying a level: the period change it makes is adaptation's,
    /// not another means' (no floor from it).
    pub(super) applying: bool,
    /// `hold_periods + window + 1` (published for a supervisor's settling time).
    pub(super) settle_periods: u32,
    /// `Exhausted` was published for the current violation.
    pub(super) exhausted: bool,
    /// The last CPU time reading and when (wall clock), for `cpu_share`.
    pub(super) cpu_mark: Option<(Instant, Duration)>,
    /// The thread's CPU time over wall-clock time between readings, smoothed.
    pub(super) cpu_share: f64,
    /// The process's idle probe (`crate::idle`), taken at the first observation on the
    /// real clock; `None` before, on a virtual clock, or if it could not start.
    pub(super) probe: Option<IdleProbe>,
    /// Whether the probe was asked for (never, with `AdaptConfig::idle_probe` off).
    pub(super) probe_asked: bool,
    /// Whether equalization may move its phase (`AdaptConfig::equalize`).
    pub(super) equalize: bool,
    /// Its place on the process's equalization board (`crate::equalize`), taken at its
    /// first periodic section on the real clock.
    pub(super) seat: Option<Seat>,
    /// The thread's CPU time and run-queue wait (equalization), opened on the
    /// component's thread at its first periodic section.
    pub(super) stats: Option<ThreadStats>,
}

/// Which axis a change by other means set (it becomes the floor of promotions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Pin {
    Period,
    Quality,
}

impl Local {
    /// `None` when there is nothing to adapt and nothing to detect.
    pub(super) fn new(config: AdaptConfig, timing: &TimingSpec) -> Option<Local> {
        let config = config.sanitized();
        let enabled = config.enabled_for(timing);
        let ladder = Ladder::new(timing, config.period_steps);
        (enabled || ladder.max_level() > 0).then(|| Local {
            enabled,
            ladder,
            detector: Detector::new(config),
            level: 0,
            floor: Floor::default(),
            applying: false,
            settle_periods: config
                .hold_periods
                .saturating_add(config.window)
                .saturating_add(1),
            exhausted: false,
            cpu_mark: None,
            cpu_share: 0.0,
            probe: None,
            probe_asked: !config.idle_probe,
            equalize: config.equalize,
            seat: None,
            stats: None,
        })
    }

    /// Load profiling (paper 3.6.1, "CPU time versus elapsed time"): the share of a
    /// core the thread used since the last CPU time reading (taken anyway for the
    /// monitor, at most every 10 ms while busy).
    pub(super) fn profile(&mut self, cpu: Duration, now: Instant) {
        if let Some((then, before)) = self.cpu_mark {
            let wall = now.saturating_duration_since(then).as_secs_f64();
            if wall >= 0.001 {
                let share = cpu.saturating_sub(before).as_secs_f64() / wall;
                self.cpu_share = 0.5 * self.cpu_share + 0.5 * share.min(1.0);
                self.cpu_mark = Some((now, cpu));
            }
        } else {
            self.cpu_mark = Some((now, cpu));
        }
    }
}

impl Runner {
    /// An `on` transition handled packets that arrived from `arrived` on: publish the
    /// response time; past `max_response` it is a late response, and a timing
    /// violation for the adaptation detector (paper 3.6).
    pub(super) fn responded(&mut self, arrived: Instant) {
        let took = self.clock.saturating_duration_since(arrived);
        let Some(bound) = self.max_response else {
            return;
        };
        if self.responses.len() == crate::monitor::RESPONSE_WINDOW {
            self.responses.pop_front();
        }
        self.responses.push_back(took);
        let mut sorted: Vec<Duration> = self.responses.iter().copied().collect();
        sorted.sort_unstable();
        let at = |share: f64| sorted[((sorted.len() - 1) as f64 * share).round() as usize];
        let (p50, p99) = (at(0.5), at(0.99));
        let late = took > bound;
        self.shared.update(|monitor| {
            let response = &mut monitor.response;
            response.p50 = p50;
            response.p99 = p99;
            response.worst = response.worst.max(took);
            response.count += 1;
            if !late {
                return Vec::new();
            }
            response.late += 1;
            vec![MonitorEvent::LateResponse {
                took,
                bound,
                total: response.late,
            }]
        });
        if self.adapt.as_ref().is_some_and(|adapt| adapt.enabled) {
            self.observe(took, bound, late);
        }
    }

    /// Feed the detector one periodic section; act on a new verdict (a component no
    /// compound supervises degrades or promotes itself, one level per verdict).
    pub(super) fn observe(&mut self, took: Duration, period: Duration, missed: bool) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        let now = Setting {
            period: self.cx.period,
            quality: self.cx.quality,
        };
        let reference = adapt
            .ladder
            .toward(now, adapt.level.saturating_sub(1), adapt.floor)
            .period
            .unwrap_or(period)
            .min(period);
        let idle = match self.time.as_virtual() {
            Some(clock) => clock.idle(),
            None => {
                if !adapt.probe_asked {
                    adapt.probe_asked = true;
                    adapt.probe = IdleProbe::shared();
                }
                adapt.probe.as_ref().is_none_or(IdleProbe::idle)
            }
        };
        let verdict = adapt.detector.observe(Observation {
            elapsed: took,
            period,
            missed,
            reference,
            idle,
        });
        let load = adapt.detector.load();
        // (Without a new verdict, the load is published with the timing counters.)
        let Some(verdict) = verdict else {
            return;
        };
        self.shared.set_pressure(verdict, load);
        if verdict != Pressure::Violation {
            adapt.exhausted = false;
        }
        if self
            .shared
            .adapt_managed
            .load(std::sync::atomic::Ordering::Acquire)
        {
            return; // The compound's supervisor decides.
        }
        let (level, max) = (adapt.level, adapt.ladder.max_level());
        let floor = adapt.ladder.floor_level(adapt.floor);
        match verdict {
            Pressure::Violation if level < max => {
                self.set_level(level + 1, "time violation", true);
            }
            Pressure::Violation if !adapt.exhausted => {
                adapt.exhausted = true;
                let step = Adaptation {
                    component: self.cx.name.to_string(),
                    action: AdaptAction::Exhausted,
                    from: level,
                    to: level,
                    period: self.cx.period,
                    quality: Some(self.cx.quality),
                    detail: "time violation at the highest level".to_owned(),
                };
                self.shared.adaptation_step(step, true, |_| {});
            }
            Pressure::Spare if level > floor => {
                self.set_level(level - 1, "spare time", true);
            }
            _ => {}
        }
    }

    /// The level the period and quality set by other means stand at (promotions stop
    /// there); 0 without adaptation.
    pub(super) fn floor_level(&self) -> u32 {
        self.adapt
            .as_ref()
            .map_or(0, |adapt| adapt.ladder.floor_level(adapt.floor))
    }

    /// Go towards adaptation level `target`, one axis at a time from where the
    /// component stands ([`Ladder::toward`]: a degradation stretches the period first,
    /// a promotion raises the quality first and stops at the floor), applied as the
    /// control port's `SetPeriod` and `SetQuality` are (events `Period`, `Quality`),
    /// then an `Adaptation` step (`logged` as for [`Runner::publish_move`]); the
    /// detector starts afresh after its hold-down.
    pub(super) fn set_level(&mut self, target: u32, why: &str, logged: bool) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        let from = adapt.level;
        let now = Setting {
            period: self.cx.period,
            quality: self.cx.quality,
        };
        let to = adapt.ladder.toward(now, target, adapt.floor);
        let level = adapt.ladder.level_of(to.period, to.quality);
        adapt.level = level;
        adapt.exhausted = false;
        let promoted = level < from;
        adapt.detector.reset(promoted);
        let load = adapt.detector.load();
        let floor = adapt.ladder.floor_level(adapt.floor);
        if to.quality != self.cx.quality {
            self.set_quality(to.quality);
        }
        if let Some(period) = to.period
            && self.cx.period != Some(period)
        {
            if let Some(adapt) = self.adapt.as_mut() {
                adapt.applying = true;
            }
            self.cx.set_period(period);
            // Publishes the period and re-anchors the schedule (the resync it asks
            // for finds the level already there).
            self.after_call();
            if let Some(adapt) = self.adapt.as_mut() {
                adapt.applying = false;
            }
        }
        self.shared.set_pressure(Pressure::Nominal, load);
        if level == from {
            return;
        }
        self.publish_move(from, level, floor, why, logged);
    }

    /// Publish a move of the adaptation level from `from` to `level` (the floor of
    /// promotions now `floor`) as an `Adaptation` step saying `why`, logged at info
    /// unless not `logged` (a move its supervisor commanded, and logged).
    pub(super) fn publish_move(&self, from: u32, level: u32, floor: u32, why: &str, logged: bool) {
        let step = Adaptation {
            component: self.cx.name.to_string(),
            action: if level < from {
                AdaptAction::Promoted
            } else {
                AdaptAction::Degraded
            },
            from,
            to: level,
            period: self.cx.period,
            quality: Some(self.cx.quality),
            detail: why.to_owned(),
        };
        self.shared.adaptation_step(step, logged, |status| {
            status.level = level;
            status.min_level = floor;
        });
    }

    /// Level `level`, set by other means on an instance its compound manages (an
    /// operator's `SetDegradation`): the floor is lifted, the level set, then both
    /// axes pinned where they stand, so that the supervisor keeps it (`min_level`).
    pub(super) fn pin_level(&mut self, level: u32) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        adapt.floor = Floor::default();
        self.set_level(
            level,
            "commanded through the control port (kept by its supervisor)",
            true,
        );
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        adapt.floor = Floor {
            quality: self.cx.quality,
            period: self
                .cx
                .period
                .filter(|period| adapt.ladder.period.is_some_and(|nominal| *period > nominal)),
        };
        let floor = adapt.ladder.floor_level(adapt.floor);
        self.shared
            .quietly(|monitor| monitor.adaptation.min_level = floor);
    }

    /// The period or quality was set by other means (a command, a `degrade` plan, the
    /// component's own `set_period`): it becomes the floor of promotions on its axis
    /// (`pin`), the level is where period and quality stand ([`Ladder::level_of`]), an
    /// `Adaptation` step says so (`why`), and the detector starts afresh.
    pub(super) fn resync_level(&mut self, why: &str, pin: Pin) {
        let Some(adapt) = self.adapt.as_mut() else {
            return;
        };
        if adapt.applying {
            return; // Adaptation's own period change: `set_level` publishes it.
        }
        match pin {
            Pin::Quality => adapt.floor.quality = self.cx.quality,
            Pin::Period => {
                adapt.floor.period = self
                    .cx
                    .period
                    .filter(|period| adapt.ladder.period.is_some_and(|nominal| *period > nominal));
            }
        }
        let floor = adapt.ladder.floor_level(adapt.floor);
        let level = adapt.ladder.level_of(self.cx.period, self.cx.quality);
        if level == adapt.level {
            self.shared
                .quietly(|monitor| monitor.adaptation.min_level = floor);
            return;
        }
        let from = adapt.level;
        let promoted = level < from;
        adapt.level = level;
        adapt.exhausted = false;
        adapt.detector.reset(promoted);
        let load = adapt.detector.load();
        self.shared.set_pressure(Pressure::Nominal, load);
        self.publish_move(from, level, floor, why, true);
    }
}
