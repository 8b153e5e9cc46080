//! What a compound's rules read, resolved once when the compound is built: every read
//! key (`inst.field`, a mapped or own variable, one of the compound's own defaults)
//! is a small id, and each thing that changes (an instance's event, a variable of the
//! supervisor, ...) knows the id of the key that names it, if a rule reads it. A
//! supervision turn's changes are then a set of ids ([`Changed`]), not of formatted
//! strings.
//!
//! A change no rule reads is not recorded: it could make no rule fire (a rule is a
//! candidate only if it reads a changed key), and a turn with such changes only does
//! what a turn without any does.

use std::collections::HashMap;

use crate::spec::Spec;

/// The ids of an instance's keys that some rule reads (`None`: no rule reads it).
#[derive(Debug, Default)]
pub(super) struct InstanceReads {
    pub(super) state: Option<usize>,
    pub(super) user_state: Option<usize>,
    pub(super) result: Option<usize>,
    pub(super) error: Option<usize>,
    pub(super) quality: Option<usize>,
    pub(super) period: Option<usize>,
    pub(super) max_response: Option<usize>,
    pub(super) priority: Option<usize>,
    /// The instance's variables, in its spec's order.
    pub(super) variables: Vec<VariableReads>,
}

/// One variable of an instance: its key's id, and the mapped variables that change
/// with it (while this instance stands for the instance they are declared on).
#[derive(Debug)]
pub(super) struct VariableReads {
    pub(super) name: &'static str,
    pub(super) key: Option<usize>,
    /// `(declared instance, mapped variable's id)` of every mapped variable (some rule
    /// reads) whose instance variable has this name.
    pub(super) mapped: Vec<(usize, usize)>,
}

/// Every key the rules read, by id, and where each comes from.
#[derive(Debug, Default)]
pub(super) struct Reads {
    /// Each key's id (the order of first appearance in the rules).
    ids: HashMap<String, usize>,
    /// Each instance's keys, by instance index.
    pub(super) instances: Vec<InstanceReads>,
    /// Each mapped variable's id (the compound's mapped variables' order).
    pub(super) mapped: Vec<Option<usize>>,
    /// Each of the supervisor's own variables' id (its spec's order).
    pub(super) own: Vec<Option<usize>>,
    /// The compound's own `result`, `error` and `quality`.
    pub(super) own_result: Option<usize>,
    pub(super) own_error: Option<usize>,
    pub(super) own_quality: Option<usize>,
    /// The time reads (`cpu_time`, `elapsed_time`, own or an instance's).
    pub(super) timed: Vec<usize>,
    /// The instances a time read names, in index order.
    pub(super) timed_instances: Vec<usize>,
}

impl Reads {
    /// The keys of rules reading `reads` (each rule's read keys), over instances
    /// `instances` (name, spec), mapped variables `mapped` (name, declared instance,
    /// its variable) and own variables `own`.
    pub(super) fn new<'a>(
        reads: impl IntoIterator<Item = &'a [String]>,
        instances: &[(&str, &'static Spec)],
        mapped: &[(&str, usize, &str)],
        own: &[&str],
    ) -> Reads {
        let mut ids: HashMap<String, usize> = HashMap::new();
        for read in reads.into_iter().flatten() {
            let next = ids.len();
            ids.entry(read.clone()).or_insert(next);
        }
        let id = |key: &str| ids.get(key).copied();
        let mapped_ids: Vec<Option<usize>> = mapped.iter().map(|(name, ..)| id(name)).collect();
        let instances_reads = instances
            .iter()
            .map(|(name, spec)| {
                let field = |field: &str| id(&format!("{name}.{field}"));
                InstanceReads {
                    state: field("state"),
                    user_state: field("user_state"),
                    result: field("result"),
                    error: field("error"),
                    quality: field("quality"),
                    period: field("period"),
                    max_response: field("max_response"),
                    priority: field("priority"),
                    variables: spec
                        .variables
                        .iter()
                        .map(|variable| VariableReads {
                            name: variable.name,
                            key: field(variable.name),
                            mapped: mapped
                                .iter()
                                .zip(&mapped_ids)
                                .filter(|((_, _, target), _)| *target == variable.name)
                                .filter_map(|((_, declared, _), id)| Some((*declared, (*id)?)))
                                .collect(),
                        })
                        .collect(),
                }
            })
            .collect();
        let mut timed: Vec<(&String, usize)> = ids
            .iter()
            .filter(|(read, _)| super::view::is_timed(read))
            .map(|(read, id)| (read, *id))
            .collect();
        timed.sort_unstable_by_key(|(_, id)| *id);
        let mut timed_instances: Vec<usize> = timed
            .iter()
            .filter_map(|(read, _)| read.split_once('.'))
            .filter_map(|(instance, _)| instances.iter().position(|(name, _)| *name == instance))
            .collect();
        timed_instances.sort_unstable();
        timed_instances.dedup();
        let timed = timed.into_iter().map(|(_, id)| id).collect();
        Reads {
            instances: instances_reads,
            mapped: mapped_ids,
            own: own.iter().map(|name| id(name)).collect(),
            own_result: id("result"),
            own_error: id("error"),
            own_quality: id("quality"),
            timed,
            timed_instances,
            ids,
        }
    }

    /// How many keys the rules read.
    pub(super) fn len(&self) -> usize {
        self.ids.len()
    }

    /// The id of read key `key`, if a rule reads it.
    pub(super) fn id(&self, key: &str) -> Option<usize> {
        self.ids.get(key).copied()
    }

    /// The ids of rule reads `reads`.
    pub(super) fn ids_of(&self, reads: &[String]) -> Vec<usize> {
        let mut ids: Vec<usize> = reads.iter().filter_map(|read| self.id(read)).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// Whether some rule reads the compound's own `result`, `error`, `quality`,
    /// `cpu_time` or `elapsed_time`.
    pub(super) fn reads_own(&self) -> bool {
        super::view::OWN_DEFAULTS
            .iter()
            .any(|key| self.ids.contains_key(*key))
    }
}

/// The read keys that changed in a supervision turn: a flag per key id, and the ids
/// set (kept between turns, so a turn allocates nothing).
#[derive(Debug, Default)]
pub(super) struct Changed {
    flags: Vec<bool>,
    set: Vec<usize>,
}

impl Changed {
    /// No change, over `keys` keys.
    pub(super) fn new(keys: usize) -> Changed {
        Changed {
            flags: vec![false; keys],
            set: Vec::with_capacity(keys),
        }
    }

    /// Key `id` changed (nothing if `None`: no rule reads it).
    pub(super) fn insert(&mut self, id: Option<usize>) {
        if let Some(id) = id
            && !std::mem::replace(&mut self.flags[id], true)
        {
            self.set.push(id);
        }
    }

    /// Keys `ids` changed.
    pub(super) fn extend(&mut self, ids: impl IntoIterator<Item = usize>) {
        for id in ids {
            self.insert(Some(id));
        }
    }

    /// Whether key `id` changed.
    pub(super) fn contains(&self, id: usize) -> bool {
        self.flags[id]
    }

    pub(super) fn is_empty(&self) -> bool {
        self.set.is_empty()
    }

    /// Forget every change.
    pub(super) fn clear(&mut self) {
        for id in self.set.drain(..) {
            self.flags[id] = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changed_is_a_set_that_clears() {
        let mut changed = Changed::new(4);
        assert!(changed.is_empty());
        changed.insert(Some(2));
        changed.insert(Some(2));
        changed.insert(None);
        changed.extend([0, 2]);
        assert!(changed.contains(0) && changed.contains(2) && !changed.contains(1));
        assert_eq!(changed.set, [2, 0]);
        changed.clear();
        assert!(changed.is_empty() && !changed.contains(2));
    }
}
