//! What `coolctl top` shows, without a terminal: every component of every node as
//! last heard, the nodes that went away, the supervision and adaptation steps as
//! they happened, the selection and the last reply. Fed by [`Board::refresh`] and
//! [`Board::step`]; read by `view`.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::{Duration, Instant};

use coolbot::{Monitor, MonitorEvent};
use serde::Serialize;

use crate::ctl::{Listed, describe};

/// How many steps the steps pane keeps.
pub const STEPS_KEPT: usize = 200;

/// One component as `top` shows it.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Its node.
    pub node: String,
    /// Its path on the node (`robot.base.motion`).
    pub path: String,
    /// How deep in its node's tree (0 for a top-level component).
    pub depth: usize,
    /// Its monitoring port, as last heard.
    pub monitor: Monitor,
    /// The share of one core its thread used between the last two refreshes (0 to
    /// 1), once two refreshes saw it.
    pub cpu_share: Option<f64>,
    /// Whether its node went away (the row shows what was last heard).
    pub lost: bool,
}

impl Row {
    /// `node/path`, as `coolctl` commands take it.
    pub fn address(&self) -> String {
        format!("{}/{}", self.node, self.path)
    }
}

/// Everything `top` shows.
#[derive(Debug, Default)]
pub struct Board {
    rows: Vec<Row>,
    /// Per `node/path`: the CPU time and when it was read, for the share.
    cpu: BTreeMap<String, (Duration, Instant)>,
    steps: VecDeque<String>,
    selected: usize,
    /// The last reply to a command, or an error.
    pub status: String,
}

/// What `coolctl top --once --json` prints.
#[derive(Debug, Serialize)]
pub struct Snapshot<'a> {
    /// The nodes alive.
    pub nodes: Vec<&'a str>,
    /// The nodes that went away while `top` watched (none for `--once`).
    pub lost: Vec<&'a str>,
    /// Every component, by node and path.
    pub components: &'a [Row],
}

impl Board {
    /// An empty board.
    pub fn new() -> Board {
        Board::default()
    }

    /// What was heard at `now`: `alive` nodes and their `listed` components. A node
    /// that is no longer alive keeps its rows, marked lost; a node that comes back
    /// replaces them.
    pub fn refresh(&mut self, alive: &[String], listed: Vec<Listed>, now: Instant) {
        let alive: BTreeSet<&str> = alive.iter().map(String::as_str).collect();
        let heard: BTreeSet<&str> = listed.iter().map(|l| l.node.as_str()).collect();
        let mut rows: Vec<Row> = self
            .rows
            .drain(..)
            .filter(|row| !heard.contains(row.node.as_str()) && !alive.contains(row.node.as_str()))
            .map(|row| Row { lost: true, ..row })
            .collect();
        for listed in listed {
            let address = format!("{}/{}", listed.node, listed.path);
            let cpu_share = self.cpu.get(&address).and_then(|(cpu, at)| {
                let wall = now.checked_duration_since(*at)?;
                (!wall.is_zero()).then(|| {
                    listed.monitor.cpu_time.saturating_sub(*cpu).as_secs_f64() / wall.as_secs_f64()
                })
            });
            self.cpu.insert(address, (listed.monitor.cpu_time, now));
            rows.push(Row {
                depth: listed.path.matches('.').count(),
                node: listed.node,
                path: listed.path,
                monitor: listed.monitor,
                cpu_share,
                lost: false,
            });
        }
        rows.sort_by(|a, b| (&a.node, &a.path).cmp(&(&b.node, &b.path)));
        self.rows = rows;
        self.selected = self.selected.min(self.rows.len().saturating_sub(1));
    }

    /// A monitoring event of the component at `node/path`: a supervision or
    /// adaptation step goes to the steps pane (newest last); other events are read
    /// at the next refresh.
    pub fn step(&mut self, address: &str, event: &MonitorEvent, at: &str) {
        if matches!(
            event,
            MonitorEvent::Supervision(_) | MonitorEvent::Adaptation(_)
        ) {
            if self.steps.len() == STEPS_KEPT {
                self.steps.pop_front();
            }
            self.steps
                .push_back(format!("{at} {address}: {}", describe(event)));
        }
    }

    /// The supervision steps the compounds' monitoring ports still hold
    /// (`Monitor::supervision`, their last steps), into the steps pane: what happened
    /// before `top` started watching (`--once` shows only these).
    pub fn seed_history(&mut self) {
        let history: Vec<String> = self
            .rows
            .iter()
            .flat_map(|row| {
                let address = row.address();
                row.monitor
                    .supervision
                    .iter()
                    .map(move |step| format!("earlier {address}: supervision: {step}"))
            })
            .collect();
        for line in history {
            if self.steps.len() == STEPS_KEPT {
                self.steps.pop_front();
            }
            self.steps.push_back(line);
        }
    }

    /// The rows, by node and path.
    pub fn rows(&self) -> &[Row] {
        &self.rows
    }

    /// The steps, oldest first.
    pub fn steps(&self) -> impl DoubleEndedIterator<Item = &String> + ExactSizeIterator {
        self.steps.iter()
    }

    /// The selected row's index.
    pub fn selected(&self) -> usize {
        self.selected
    }

    /// The selected row, if any (a lost one too: commands to it fail with a reason).
    pub fn selected_row(&self) -> Option<&Row> {
        self.rows.get(self.selected)
    }

    /// The address of the selected component, to command; why not when there is none
    /// or its node is lost (no command is sent to a node that is not there: it could
    /// only time out).
    pub fn command_target(&self) -> Result<String, String> {
        match self.selected_row() {
            None => Err("no component selected".to_owned()),
            Some(row) if row.lost => Err(format!(
                "node `{}` is lost: no command sent to `{}`",
                row.node,
                row.address()
            )),
            Some(row) => Ok(row.address()),
        }
    }

    /// Move the selection by `delta` rows, within the table.
    pub fn select(&mut self, delta: isize) {
        let last = self.rows.len().saturating_sub(1);
        self.selected = self.selected.saturating_add_signed(delta).min(last);
    }

    /// What `--once --json` prints.
    pub fn snapshot<'a>(&'a self, alive: &'a [String]) -> Snapshot<'a> {
        let lost: BTreeSet<&str> = self
            .rows
            .iter()
            .filter(|row| row.lost)
            .map(|row| row.node.as_str())
            .collect();
        Snapshot {
            nodes: alive.iter().map(String::as_str).collect(),
            lost: lost.into_iter().collect(),
            components: &self.rows,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A monitor as a node would publish it for a running component.
    pub(crate) fn monitor(name: &str, cpu_ms: u64) -> Monitor {
        let zero = serde_json::json!({ "secs": 0, "nanos": 0 });
        let cpu =
            serde_json::json!({ "secs": cpu_ms / 1000, "nanos": (cpu_ms % 1000) * 1_000_000 });
        serde_json::from_value(serde_json::json!({
            "name": name, "state": "Running", "user_state": "working", "result": "None",
            "error": null, "variables": [], "cpu_time": cpu, "elapsed_time": zero,
            "missed_deadlines": 0, "overruns": 0, "overflows": 0, "port_overflows": [],
            "quality": 0, "period": { "secs": 0, "nanos": 20_000_000 }, "max_response": null,
            "priority": 0, "os_priority": "Inherited", "dropped_events": 0,
            "supervision": [], "supervision_steps": 0,
        }))
        .expect("a monitor")
    }

    fn listed(node: &str, path: &str, cpu_ms: u64) -> Listed {
        Listed {
            node: node.to_owned(),
            path: path.to_owned(),
            monitor: monitor(path.rsplit('.').next().unwrap_or(path), cpu_ms),
        }
    }

    #[test]
    fn a_node_that_goes_keeps_its_rows_marked_lost_until_it_comes_back() {
        let t0 = Instant::now();
        let mut board = Board::new();
        let alive = vec!["a".to_owned(), "b".to_owned()];
        board.refresh(&alive, vec![listed("a", "x", 0), listed("b", "y", 0)], t0);
        assert!(board.rows().iter().all(|row| !row.lost));
        // `b` goes.
        board.refresh(&alive[..1], vec![listed("a", "x", 0)], t0);
        let lost: Vec<_> = board
            .rows()
            .iter()
            .filter(|r| r.lost)
            .map(|r| r.address())
            .collect();
        assert_eq!(lost, ["b/y"]);
        assert_eq!(board.snapshot(&alive[..1]).lost, ["b"]);
        // A lost row is not commanded; a live one is.
        assert_eq!(board.command_target(), Ok("a/x".to_owned()));
        board.select(1);
        assert_eq!(
            board.command_target(),
            Err("node `b` is lost: no command sent to `b/y`".to_owned())
        );
        board.select(-1);
        // `b` comes back with another component: the old rows go.
        board.refresh(&alive, vec![listed("a", "x", 0), listed("b", "z", 0)], t0);
        let rows: Vec<_> = board.rows().iter().map(|r| (r.address(), r.lost)).collect();
        assert_eq!(rows, [("a/x".to_owned(), false), ("b/z".to_owned(), false)]);
    }

    #[test]
    fn the_cpu_share_is_cpu_time_over_wall_time_between_refreshes() {
        let t0 = Instant::now();
        let mut board = Board::new();
        let alive = vec!["a".to_owned()];
        board.refresh(&alive, vec![listed("a", "x", 100)], t0);
        assert_eq!(board.rows()[0].cpu_share, None);
        board.refresh(
            &alive,
            vec![listed("a", "x", 350)],
            t0 + Duration::from_secs(1),
        );
        let share = board.rows()[0].cpu_share.expect("a share");
        assert!((share - 0.25).abs() < 1e-9, "{share}");
    }

    #[test]
    fn only_supervision_and_adaptation_steps_reach_the_pane_and_the_selection_stays_in_the_table() {
        let mut board = Board::new();
        board.step("a/x", &MonitorEvent::Configured, "0.0s");
        board.step(
            "a/x",
            &MonitorEvent::Supervision(coolbot::Supervision {
                instance: "w".to_owned(),
                step: coolbot::Step::Failed,
                detail: "boom".to_owned(),
            }),
            "1.5s",
        );
        let steps: Vec<_> = board.steps().cloned().collect();
        assert_eq!(steps.len(), 1);
        assert!(steps[0].starts_with("1.5s a/x: supervision: "), "{steps:?}");
        let alive = vec!["a".to_owned()];
        board.refresh(
            &alive,
            vec![listed("a", "x", 0), listed("a", "x.y", 0)],
            Instant::now(),
        );
        board.select(5);
        assert_eq!(board.selected(), 1);
        board.select(-9);
        assert_eq!(board.selected(), 0);
        assert_eq!(board.rows()[1].depth, 1);
    }
}
