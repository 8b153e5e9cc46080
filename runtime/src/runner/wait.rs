//! The wait between turns on a component's own thread: spinning, yielding, parking.

use super::*;

impl Runner {
    /// The thread's body. The runner stays where it was boxed: moved onto the
    /// thread's stack, it would take a page or more of every component thread's
    /// stack, as many as the frames around it happen to need.
    pub(crate) fn run(mut self: Box<Self>) {
        self.bell.attach();
        self.claim_sends();
        self.bind_clock();
        self.run_loop();
        // (Dropping the runner leaves the clock.)
    }

    /// This thread sends on the component's data outputs without their sinks' lock
    /// (`crate::port::Sinks`).
    pub(super) fn claim_sends(&self) {
        for output in &self.outputs {
            output.claim_sends();
        }
    }

    pub(super) fn run_loop(&mut self) {
        crate::thread::set_timer_slack();
        self.scheduling = Some(Scheduling::of_current_thread());
        let mut priority = 0;
        self.shared.quietly(|monitor| priority = monitor.priority);
        self.apply_priority(priority);
        self.begin();
        loop {
            match self.turn() {
                Turn::Dead => break,
                Turn::Stopped => {
                    // Nothing runs: wait for the next ring (a command, or an arrival
                    // that only needs to stay where it is).
                    if !self.bell.spin() {
                        self.clock = self.time.now();
                        self.update_cpu(false);
                        self.settle();
                        self.bell.park_until(None);
                    }
                }
                // After a piece of work, wait at once when nothing else is known to be
                // waiting, instead of going round for a second full look: anything
                // that arrived since the turn's `clear` rang the bell, so the wait
                // returns at once for it, and a timer already due makes the wait's
                // deadline past.
                Turn::Worked if !self.idle() => {}
                Turn::Worked | Turn::Idle => self.block(),
            }
        }
        self.end();
    }

    /// What the thread does before its first turn (after its OS scheduling is set):
    /// publish the adaptation settings and the variables, run `start` and go to
    /// `ready` (or `starting_error`). The harness (`crate::harness`) calls it too.
    pub(super) fn idle(&self) -> bool {
        self.state == State::Running
            && !self.cx.end_requested
            && self.pending_choice.is_none()
            && (self.polled || !self.bell.is_rung())
            && !self.tracks.iter().any(|track| track.pending)
            && !self.pull_requests_waiting()
    }

    /// Whether a source of work has something for the thread: a command, an arrival
    /// not seen yet, a pull request. Everything that rings the bell of a component
    /// that is not a compound's has one of these behind it (a compound's bell is also
    /// rung by its instances' events and its `Waker`s, which leave nothing to look at).
    pub(super) fn work_waiting(&self) -> bool {
        !self.control.is_empty()
            || self
                .inputs
                .iter()
                .zip(&self.tracks)
                .any(|(input, track)| input.arrivals() != track.seen)
            || self.pull_requests_waiting()
            || self.bell.sources_ready()
    }

    /// Whether a pull request waits at one of the component's pull outputs.
    pub(super) fn block(&mut self) {
        let deadline = self.next_due();
        // On a virtual clock, data to retry moving waits in real time. The automaton is
        // asked only then: never on the real clock, where this is a hot path.
        let retry =
            (self.supervised && self.state == State::Running && self.time.as_virtual().is_some())
                .then(|| self.automaton.retries_data())
                .flatten()
                .map(|soon| later(Instant::now(), soon));
        // One wait on the doorbell, rung by commands, deliveries and pull requests; the
        // loop then looks at the control port first (the priority rule above). With a
        // timer due, park at once (a periodic thread sleeps like a bare one); waiting
        // for input only, spin first (`wait_for_input`). The timing counters are
        // published (a lock of the monitor) only when the thread is about to sleep.
        if deadline.is_none() && retry.is_none() {
            self.settle();
            self.wait_for_input();
            return;
        }
        self.update_cpu(false);
        if let Some(clock) = self.time.as_virtual() {
            // A virtual timer: never a real timeout. With the timer due later, settle
            // and wait for a ring (the clock rings when it advances).
            // One reading for the check and the report: settled at `now` means
            // nothing was due at `now`.
            let now = clock.now();
            if deadline.is_none_or(|due| due > now) {
                if let Some(id) = self.on_clock {
                    clock.settled(id, now, &|| !self.control.is_empty());
                }
                self.bell.park_until(retry);
            }
            return;
        }
        self.bell.park_until(deadline);
    }

    /// Wait for work with no timer due: spin for [`SPIN`], then yield a few times, then
    /// park. An idle component spins once, a few microseconds, then sleeps: it burns no
    /// CPU while nothing comes.
    ///
    /// While it spins, a component that is not a compound's looks at its sources of
    /// work themselves (`work_waiting`: the control queue, the arrival counters, the
    /// pull queues) rather than at the bell, and the turn that follows does not clear
    /// the bell. The bell then stays rung through a fast exchange, and every ring is a
    /// plain load of a cache line that no one writes: the ringer's swap and the
    /// thread's clear, two cache-line transfers per packet, are saved. Nothing is lost:
    /// before it parks, the thread clears the bell and looks at every source once more,
    /// so the doorbell's protocol (`wake.rs`, `Doorbell`) holds from there on. A
    /// compound's bell is also rung by events that leave no source to look at, and so
    /// is any component's on a virtual clock when the clock advances: those spin on
    /// the bell.
    pub(super) fn wait_for_input(&mut self) {
        // On a virtual clock the bell also says the clock advanced (no source shows
        // that): spin on the bell, or an advance rung while polling would be cleared
        // unseen and the component never settle at the new time.
        let polling = !self.supervised && self.time.is_real();
        let found = |runner: &Runner| {
            if polling {
                runner.work_waiting()
            } else {
                runner.bell.is_rung()
            }
        };
        if polling && self.work_waiting() {
            // Work came during the turn: the component is behind a faster producer.
            // Let it deliver a batch undisturbed before the next turn (see
            // `BATCH_PAUSE`), longer each turn in a row that ends behind.
            for _ in 0..self.batch_pause {
                std::hint::spin_loop();
            }
            self.batch_pause = next_pause(self.batch_pause, true);
            self.found_by_polling = true;
            return;
        }
        self.batch_pause = next_pause(self.batch_pause, false);
        let idle_since = Instant::now();
        let mut read_at = idle_since;
        'spin: loop {
            for _ in 0..SPIN_BATCH {
                if found(self) {
                    self.found_by_polling = polling;
                    self.found_at = (self.untimed && self.time.is_real()).then_some(read_at);
                    return;
                }
                std::hint::spin_loop();
            }
            read_at = Instant::now();
            if read_at.saturating_duration_since(idle_since) >= SPIN {
                break 'spin;
            }
        }
        if polling {
            // From here on, rings are what wakes the thread: clear, then look.
            self.bell.clear();
            if self.work_waiting() {
                return;
            }
        }
        for _ in 0..YIELD_ROUNDS {
            if self.bell.is_rung() {
                return;
            }
            std::thread::yield_now();
        }
        self.update_cpu(false);
        self.bell.park_until(None);
    }
}

/// The pause before the turn after this one, from this one's: doubled after a turn
/// that ended `behind` a faster producer (up to `BATCH_PAUSE_MAX`), back to
/// `BATCH_PAUSE` after one that did not.
fn next_pause(pause: u32, behind: bool) -> u32 {
    if behind {
        pause.saturating_mul(2).min(BATCH_PAUSE_MAX)
    } else {
        BATCH_PAUSE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pause_behind_a_producer_doubles_up_to_its_cap_and_resets_once_caught_up() {
        let mut pauses = vec![BATCH_PAUSE];
        for _ in 0..5 {
            let last = pauses[pauses.len() - 1];
            pauses.push(next_pause(last, true));
        }
        assert_eq!(pauses, [32, 64, 128, 256, 512, 512]);
        let pause = BATCH_PAUSE_MAX;
        assert_eq!(next_pause(pause, false), BATCH_PAUSE);
    }
}
