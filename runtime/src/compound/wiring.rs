//! Who stands for each instance now (itself, its substitute, its redundant group's
//! leader), and the connections that follow: declared connections moved in one step
//! with their queues, redundant members fed together, their data outputs merged into
//! one stream, exported ports following their instances.

use crate::automaton::Fault;
use crate::port::{ErasedInput, ErasedOutput};
use crate::system::ConnectError;

use super::error::{ExportError, RunError};
use super::links::{Link, LinkVia, MergedPort};
use super::state::{Compound, Status};

impl Compound {
    /// Who stands for instance `index` now.
    pub(super) fn route(&self, index: usize) -> usize {
        let instance = &self.instances[index];
        if let Some(group) = instance.group {
            return self.leaders[group];
        }
        if let Some(substitute) = instance.substitute
            && instance.status != Status::Active
            && self.instances[substitute].status == Status::Active
        {
            return substitute;
        }
        index
    }

    pub(super) fn routed(&self, address: &str) -> String {
        let Some((instance, port)) = address.split_once('.') else {
            return address.to_owned();
        };
        match self.instances.iter().position(|i| i.name == instance) {
            Some(index) => format!("{}.{port}", self.instances[self.route(index)].name),
            None => address.to_owned(),
        }
    }

    /// Make the connections match the arrangement: each declared connection between
    /// the instances standing for its ends now. A connection whose end moved (to a
    /// stand-in, or back) is replaced in one step, with the packets queued at a
    /// replaced input (`System::replace_link`): no packet is lost meanwhile.
    pub(super) fn rewire(&mut self) -> Result<(), Fault> {
        // Moves wait in `self.moves` until a rewiring completes: one that fails half
        // way leaves them for the next (at the compound's restart).
        let moves = self.update_standing();
        self.moves.extend(moves);
        self.make_merges()?;
        let mut wanted: Vec<Option<Link>> = Vec::with_capacity(self.links.len());
        // Connections to a redundant group's inputs go to every live member; from a
        // group's data output, the merged stream feeds the consumers.
        let mut fanned: Vec<Link> = Vec::new();
        let mut merged: Vec<(usize, usize, String, Option<LinkVia>)> = Vec::new();
        for (index, link) in self.links.iter().enumerate() {
            if let Some(merge) = self.merge_of(&link.from) {
                for to in self.fed(&link.to) {
                    merged.push((merge, index, to, link.link_via.clone()));
                }
                wanted.push(None);
                continue;
            }
            if self.in_group(&link.to) {
                let from = self.routed(&link.from);
                for to in self.fed(&link.to) {
                    fanned.push(Link {
                        from: from.clone(),
                        to,
                        via: link.via.clone(),
                        link_via: None,
                    });
                }
                wanted.push(None);
                continue;
            }
            let routed = Link {
                from: self.routed(&link.from),
                to: self.routed(&link.to),
                via: link.via.clone(),
                link_via: None,
            };
            let duplicate = wanted.iter().flatten().any(|w| w.ends() == routed.ends());
            wanted.push((!duplicate).then_some(routed));
        }
        self.wired.resize(self.links.len(), None);
        let Some(system) = self.system.as_mut() else {
            return Ok(());
        };
        let name = &self.name;
        let error = |source: ConnectError| {
            Fault::from(RunError::Wiring {
                compound: name.clone(),
                source,
            })
        };
        let plain = |output: &ErasedOutput, input: &ErasedInput, old: Option<&ErasedInput>| {
            output.type_id == input.type_id
                && match old {
                    Some(old) => old.kind == input.kind && output.relink(old, input),
                    None => output.link(input),
                }
        };
        // A connection whose link now has the same ends as an earlier link's goes
        // first (unless another link still wants it); then each link's connection is
        // kept, replaced in one step, or made.
        for index in 0..self.wired.len() {
            if wanted[index].is_none()
                && let Some(link) = self.wired[index].take()
                && !wanted.iter().flatten().any(|w| w.ends() == link.ends())
            {
                system.disconnect(&link.from, &link.to).map_err(error)?;
            }
        }
        for (index, new) in wanted.iter().enumerate() {
            let Some(new) = new else {
                continue;
            };
            let old = self.wired[index].take();
            // The same connection may have been made for another link (whose ends it
            // had before): it is kept as it is.
            let made = self.wired.iter().flatten().any(|w| w.ends() == new.ends());
            match old {
                Some(old) if old.ends() == new.ends() => {}
                Some(old) if !made => {
                    let ends = (old.from.as_str(), old.to.as_str());
                    match &new.via {
                        Some(via) => via(system, Some(ends), &new.from, &new.to),
                        None => system.replace_link(ends, &new.from, &new.to, &plain),
                    }
                    .map_err(error)?;
                }
                old => {
                    if let Some(old) = old
                        && !wanted.iter().flatten().any(|w| w.ends() == old.ends())
                    {
                        system.disconnect(&old.from, &old.to).map_err(error)?;
                    }
                    if !made {
                        match &new.via {
                            Some(via) => via(system, None, &new.from, &new.to),
                            None => system.connect(&new.from, &new.to),
                        }
                        .map_err(error)?;
                    }
                }
            }
            self.wired[index] = Some(new.clone());
        }
        // Fanned connections: those no longer wanted go first (a poster or last input
        // takes one producer), then the new ones are made.
        let stale: Vec<(String, String)> = self
            .fanned
            .iter()
            .filter(|old| {
                !fanned
                    .iter()
                    .any(|new| new.ends() == (old.0.as_str(), old.1.as_str()))
            })
            .cloned()
            .collect();
        for (from, to) in stale {
            system.disconnect(&from, &to).map_err(error)?;
            self.fanned.retain(|old| *old != (from.clone(), to.clone()));
        }
        for new in &fanned {
            let ends = (new.from.clone(), new.to.clone());
            if self.fanned.contains(&ends) {
                continue;
            }
            match &new.via {
                Some(via) => via(system, None, &new.from, &new.to),
                None => system.connect(&new.from, &new.to),
            }
            .map_err(error)?;
            self.fanned.push(ends);
        }
        // The merged streams' consumers: new ones linked before stale ones unlinked. A
        // declared connection's one consumer replaced by another (a stand-in, or the
        // original back) moves in one step with its queue, as any connection's does.
        for (merge, link, to, via) in &merged {
            if self.merged.iter().any(|(m, _, t, _)| m == merge && t == to) {
                continue;
            }
            let input = system.input_port(to).map_err(error)?;
            let output = self.merges[*merge].merge.output();
            let single = merged.iter().filter(|(_, l, _, _)| l == link).count() == 1;
            let replaced = self.merged.iter().position(|(m, l, t, _)| {
                m == merge && l == link && !merged.iter().any(|(m2, _, t2, _)| m2 == m && t2 == t)
            });
            // (Through a converter too: it stays on the connection.)
            if single
                && let Some(position) = replaced
                && self.merged[position].3.kind == input.kind
            {
                let old = &self.merged[position].3;
                let moved = match via {
                    Some(via) => via(&output, Some(old), &input),
                    None => output.type_id == input.type_id && output.relink(old, &input),
                };
                if moved {
                    self.merged[position] = (*merge, *link, to.clone(), input);
                    continue;
                }
            }
            let linked = match via {
                Some(via) => via(&output, None, &input),
                None => output.type_id == input.type_id && output.link(&input),
            };
            if !linked {
                return Err(RunError::MergedConsumer {
                    compound: name.clone(),
                    port: self.merges[*merge].port.clone(),
                    to: to.clone(),
                }
                .into());
            }
            self.merged.push((*merge, *link, to.clone(), input));
        }
        let merges = &self.merges;
        self.merged.retain(|(merge, _, to, input)| {
            let keep = merged.iter().any(|(m, _, t, _)| m == merge && t == to);
            if !keep {
                merges[*merge].merge.output().unlink(input);
            }
            keep
        });
        for index in 0..self.exports.len() {
            let target = self.exports[index].target().to_owned();
            let Some(system) = self.system.as_ref() else {
                break;
            };
            let followed = if self.exports[index].is_input() {
                let inputs: Result<Vec<ErasedInput>, ConnectError> = self
                    .fed(&target)
                    .iter()
                    .map(|address| system.input_port(address))
                    .collect();
                inputs
                    .map_err(ExportError::from)
                    .and_then(|inputs| self.exports[index].follow_inputs(inputs))
            } else {
                let output = match self.merge_of(&target) {
                    Some(merge) => Ok(self.merges[merge].merge.output()),
                    None => system
                        .output_port(&self.routed(&target))
                        .map_err(ExportError::from),
                };
                output.and_then(|output| self.exports[index].follow_output(output))
            };
            followed.map_err(|source| RunError::Export {
                compound: self.name.clone(),
                target,
                source,
            })?;
        }
        // Last, once every consumer reads the stand-in: the pulls waiting at the
        // instance it replaces.
        for (from, to) in std::mem::take(&mut self.moves) {
            self.move_pulls(from, to);
        }
        Ok(())
    }

    /// Whether `address` (`instance.port`) is a port of a redundant group's member.
    pub(super) fn in_group(&self, address: &str) -> bool {
        self.index_of(address)
            .is_some_and(|index| self.instances[index].group.is_some())
    }

    pub(super) fn index_of(&self, address: &str) -> Option<usize> {
        let (instance, _) = address.split_once('.')?;
        self.instances.iter().position(|i| i.name == instance)
    }

    /// The inputs a connection or export to input `address` feeds now: for a member
    /// of a redundant group, the same input of every live member (of the leader if
    /// none is live); else the input of whoever stands for the instance.
    pub(super) fn fed(&self, address: &str) -> Vec<String> {
        let (Some(index), Some((_, port))) = (self.index_of(address), address.split_once('.'))
        else {
            return vec![address.to_owned()];
        };
        match self.instances[index].group {
            Some(group) => {
                let live: Vec<String> = self.groups[group]
                    .iter()
                    .filter(|m| self.instances[**m].status == Status::Active)
                    .map(|m| format!("{}.{port}", self.instances[*m].name))
                    .collect();
                if live.is_empty() {
                    vec![format!(
                        "{}.{port}",
                        self.instances[self.leaders[group]].name
                    )]
                } else {
                    live
                }
            }
            None => vec![self.routed(address)],
        }
    }

    /// The merge of the data output at `address`, if it is a redundant member's.
    pub(super) fn merge_of(&self, address: &str) -> Option<usize> {
        let index = self.index_of(address)?;
        let group = self.instances[index].group?;
        let (_, port) = address.split_once('.')?;
        self.merges
            .iter()
            .position(|m| m.group == group && m.port == port)
    }

    /// Make the merge of every redundant member's data output that a connection or an
    /// export reads (once: the lanes stay attached to the members' outputs).
    pub(super) fn make_merges(&mut self) -> Result<(), Fault> {
        let Some(system) = self.system.as_ref() else {
            return Ok(());
        };
        let sources = self.links.iter().map(|link| link.from.clone()).chain(
            self.exports
                .iter()
                .filter(|e| !e.is_input())
                .map(|e| e.target().to_owned()),
        );
        let mut made = Vec::new();
        for address in sources {
            let (Some(index), Some((_, port))) = (self.index_of(&address), address.split_once('.'))
            else {
                continue;
            };
            let Some(group) = self.instances[index].group else {
                continue;
            };
            if self
                .merges
                .iter()
                .chain(&made)
                .any(|m: &MergedPort| m.group == group && m.port == port)
            {
                continue;
            }
            let members = &self.groups[group];
            let wiring = |source| RunError::Wiring {
                compound: self.name.clone(),
                source,
            };
            let first = system
                .output_port(&format!("{}.{port}", self.instances[members[0]].name))
                .map_err(wiring)?;
            let Some(merge) = first.merge(members.len()) else {
                continue; // A tick or poster output: its consumers follow the leader.
            };
            for (lane, member) in members.iter().enumerate() {
                let output = system
                    .output_port(&format!("{}.{port}", self.instances[*member].name))
                    .map_err(wiring)?;
                if !merge.attach(lane, &output) {
                    return Err(RunError::MergedMember {
                        compound: self.name.clone(),
                        output: format!("{}.{port}", self.instances[*member].name),
                    }
                    .into());
                }
            }
            let leader = members
                .iter()
                .position(|m| *m == self.leaders[group])
                .unwrap_or(0);
            merge.reset(leader);
            made.push(MergedPort {
                group,
                port: port.to_owned(),
                merge,
            });
        }
        self.merges.extend(made);
        Ok(())
    }

    /// Member `member` of redundant group `group` leads it from now on: the merged
    /// streams go on from its backlog. Returns the packets replayed and missing.
    pub(super) fn lead(&mut self, group: usize, member: usize) -> (u64, u64) {
        self.leaders[group] = member;
        let lane = self.groups[group]
            .iter()
            .position(|m| *m == member)
            .unwrap_or(0);
        self.merges
            .iter()
            .filter(|m| m.group == group)
            .map(|m| m.merge.lead(lane))
            .fold((0, 0), |(r, g), (r2, g2)| (r + r2, g + g2))
    }

    /// Record who stands for each instance now in the view (for mapped variables);
    /// if that changed, rules reading mapped variables are evaluated on this turn.
    /// Returns the moves `(from, to)` of the instances that stopped and started
    /// standing for one (their waiting pull requests follow: [`Compound::move_pulls`]).
    pub(super) fn update_standing(&mut self) -> Vec<(usize, usize)> {
        let standing: Vec<usize> = (0..self.instances.len()).map(|i| self.route(i)).collect();
        let mut moves = Vec::new();
        if standing != self.view.standing {
            for (before, now) in self.view.standing.iter().zip(&standing) {
                if before != now && !moves.contains(&(*before, *now)) {
                    moves.push((*before, *now));
                }
            }
            self.view.standing = standing;
            self.restood = true;
        }
        moves
    }

    /// Instance `to` stands where `from` stood: the pull requests waiting at `from`'s
    /// pull outputs (their consumers now read `to`) go to `to`'s same outputs, so a
    /// pull in flight is answered by the stand-in instead of waiting at an instance
    /// that no longer feeds its puller. A request `to` cannot queue (its queue is
    /// full) is dropped with a warning: its puller gets `PullError::Timeout`.
    fn move_pulls(&self, from: usize, to: usize) {
        let Some(system) = self.system.as_ref() else {
            return;
        };
        let (old, new) = (&self.instances[from].name, &self.instances[to].name);
        for output in self.instances[from].spec.outputs.iter().filter(|o| o.pull) {
            let ports = (
                system.output_port(&format!("{old}.{}", output.name)),
                system.output_port(&format!("{new}.{}", output.name)),
            );
            if let (Ok(from_port), Ok(to_port)) = ports {
                let (moved, refused) = crate::port::move_requests(&from_port, &to_port);
                if moved > 0 {
                    tracing::info!(compound = %self.name, "{moved} pull request(s) waiting at `{old}.{}` moved to `{new}`", output.name);
                }
                if refused > 0 {
                    crate::limited!(
                        &self.name,
                        |held| tracing::warn!(compound = %self.name, "{refused} pull request(s) waiting at `{old}.{}` dropped: `{new}`'s request queue is full{held}", output.name)
                    );
                }
            }
        }
    }
}
