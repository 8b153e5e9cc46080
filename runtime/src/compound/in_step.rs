//! Redundant members in step. A merged stream numbers each member's packets in the
//! order it sends them, which matches the other members' numbers only while every
//! member has received every packet. A member that stalled and was left out of
//! packets at a compound's exported input since it joined its group is out of step:
//! it may no longer lead or stand by, since a failover to it would skip or double
//! packets of the stream without a count. It is taken out of the group and
//! resynchronized through the recovery queue; when it recovers it joins again at the
//! stream's number. (Losses by a member's own overflow policy are the description's
//! choice and leave it in the group: see `docs/runtime.md`, "Redundancy".)

use crate::monitor::{Command, Step};
use crate::table::Controllable;

use super::state::{Compound, Status};

impl Compound {
    /// The packets member `index` was left out of since it joined its group.
    pub(super) fn lost_since_join(&self, index: usize) -> u64 {
        let instance = &self.instances[index];
        self.system.as_ref().map_or(0, |system| {
            system
                .left_behind(&instance.name)
                .saturating_sub(instance.left_at_join)
        })
    }

    /// Whether member `index` may take its group's lead: active, not failed (its
    /// policy not run yet: it may have failed to start), and in step.
    pub(super) fn can_lead(&self, index: usize) -> bool {
        self.instances[index].status == Status::Active
            && !self.failing(index)
            && self.lost_since_join(index) == 0
    }

    /// Whether instance `index` is in `running_error` or `starting_error` as the
    /// compound last saw it.
    pub(super) fn failing(&self, index: usize) -> bool {
        matches!(
            self.view.instances[index].state,
            crate::table::State::RunningError | crate::table::State::StartingError
        )
    }

    /// Member `index` joins its group (at the compound's start, or recovered): its
    /// losses count from now.
    pub(super) fn joined(&mut self, index: usize) {
        let name = &self.instances[index].name;
        let lost = self
            .system
            .as_ref()
            .map_or(0, |system| system.left_behind(name));
        self.instances[index].left_at_join = lost;
    }

    /// Take the active members of redundant groups that were left out of packets out
    /// of their groups. A member that leads hands the lead to a member still in step, if
    /// one is; if none is, it keeps leading (the stream is what it sends: its losses
    /// are counted at its inputs). Returns whether the arrangement changed (the caller
    /// rewires).
    pub(super) fn keep_in_step(&mut self) -> bool {
        let mut changed = false;
        for group in 0..self.groups.len() {
            let active: Vec<usize> = self.groups[group]
                .iter()
                .copied()
                .filter(|m| self.instances[*m].status == Status::Active)
                .collect();
            let lossy: Vec<(usize, u64)> = active
                .iter()
                .map(|m| (*m, self.lost_since_join(*m)))
                .filter(|(_, lost)| *lost > 0)
                .collect();
            if lossy.is_empty() {
                continue;
            }
            changed = true;
            let leader = self.leaders[group];
            let in_step = active
                .iter()
                .copied()
                .find(|m| !lossy.iter().any(|(l, _)| l == m));
            for (member, lost) in &lossy {
                if *member != leader {
                    self.resync(*member, format!("left out of {lost} input packet(s)"));
                }
            }
            let Some(&(_, lost)) = lossy.iter().find(|(m, _)| *m == leader) else {
                continue;
            };
            match in_step {
                Some(next) => {
                    let by = self.instances[next].name.clone();
                    self.resync(leader, format!("left out of {lost} input packet(s)"));
                    let (replayed, missing) = self.lead(group, next);
                    self.step(
                        leader,
                        Step::Substituted { by },
                        takeover(replayed, missing),
                    );
                }
                // Every active member lost packets (the others were taken out
                // above): nobody has what it lost, and it leads on from here.
                None => self.joined(leader),
            }
        }
        changed
    }

    /// Member `index` is out of step: published (`OutOfStep`), commanded to `ready`
    /// without waiting (it may be hung), its queued inputs discarded (counted lost at
    /// them), and queued for recovery (its inputs are disconnected at the rewiring).
    fn resync(&mut self, index: usize, detail: String) {
        self.step(index, Step::OutOfStep, detail);
        let handle = &self.instances[index].handle;
        if let Err(rejected) = handle.post(Command::SetState(Controllable::Ready)) {
            crate::limited!(
                &self.name,
                |held| tracing::warn!(compound = %self.name, "{rejected}{held}")
            );
        }
        if let Some(system) = self.system.as_ref() {
            system.discard_queued(&self.instances[index].name);
        }
        self.enqueue(index);
        self.step(index, Step::Enqueued, "");
    }
}

/// The detail of a `Substituted` step in a redundant group: what the new leader's
/// backlog gave the stream, and what the stream misses.
pub(super) fn takeover(replayed: u64, missing: u64) -> String {
    let mut detail = String::new();
    if replayed > 0 {
        detail = format!("{replayed} packet(s) of its backlog continued the stream");
    }
    if missing > 0 {
        detail.push_str(&format!(
            "; {missing} packet(s) missing from the stream (beyond its backlog), counted lost at its consumers"
        ));
    }
    detail
}
