//! What `coolctl top` shows, without a terminal: every component of every node as
//! last heard, the nodes that went away, the supervision and adaptation steps as
//! they happened (the newest [`STEPS_PER_INSTANCE`] of each instance, routine ones
//! hidden on demand, scrolled), the selection, the pane the keys move, and the last
//! reply. Fed by [`Board::refresh`] and [`Board::step`]; read by `view`.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::{Duration, Instant};

use coolbot::{Monitor, MonitorEvent, Supervision};
use serde::Serialize;

use crate::ctl::{Listed, describe};

/// How many steps the steps pane keeps of each instance (the newest): a chatty
/// instance's routine steps never push another's out.
pub const STEPS_PER_INSTANCE: usize = 50;

/// How many steps the steps pane keeps in all (the newest).
pub const STEPS_KEPT: usize = 2000;

/// One line of the steps pane.
#[derive(Debug, Clone)]
struct StepLine {
    /// Whose step: `node/compound:instance` (or the component an adaptation step is
    /// about).
    whose: String,
    /// A routine step (a supervisor's command taken, a recovery retry that failed),
    /// hidden when the operator asks.
    routine: bool,
    text: String,
}

/// Which pane the arrow keys move.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Focus {
    /// The component table: the keys select a row.
    #[default]
    Components,
    /// The steps pane: the keys scroll it.
    Steps,
}

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

/// Where a row sorts: by node, then by path, except that the members of an
/// execution group (siblings, in one compound or at the top of a node) sit
/// together, in the order they run, where the first of them by name would be.
fn order(row: &Row) -> (String, Vec<(String, usize)>) {
    let mut key: Vec<(String, usize)> = row.path.split('.').map(|s| (s.to_owned(), 0)).collect();
    if let (Some(group), Some(last)) = (&row.monitor.group, key.last_mut()) {
        let first = group.members.iter().min().unwrap_or(&last.0).clone();
        let place = group.members.iter().position(|m| *m == last.0);
        *last = (first, place.map_or(usize::MAX, |p| p + 1));
    }
    (row.node.clone(), key)
}

/// One execution group as `top` sums it up (under the component table).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupLine {
    /// Its node.
    pub node: String,
    /// The path of the compound it is in (empty at the top of a node).
    pub within: String,
    /// What its members' monitors show of it (the newest).
    pub status: coolbot::GroupStatus,
}

impl std::fmt::Display for GroupLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = &self.status;
        let place = if self.within.is_empty() {
            self.node.clone()
        } else {
            format!("{}/{}", self.node, self.within)
        };
        write!(
            f,
            "thread {} in {place}: {}; cycle {}, worst {}",
            g.name,
            g.members.join(" > "),
            short(g.last_cycle),
            short(g.worst_cycle)
        )?;
        if let Some(period) = g.period {
            write!(f, ", period {}", short(period))?;
        }
        write!(f, ", {} overruns in {} cycles", g.overruns, g.cycles)
    }
}

/// A duration as `top` prints a cycle: microseconds under a millisecond.
pub fn short(d: Duration) -> String {
    if d < Duration::from_millis(1) {
        format!("{}us", d.as_micros())
    } else if d < Duration::from_secs(1) {
        format!("{:.1}ms", d.as_secs_f64() * 1e3)
    } else {
        format!("{:.1}s", d.as_secs_f64())
    }
}

/// Everything `top` shows.
#[derive(Debug, Default)]
pub struct Board {
    rows: Vec<Row>,
    /// Per `node/path`: the CPU time and when it was read, for the share.
    cpu: BTreeMap<String, (Duration, Instant)>,
    steps: VecDeque<StepLine>,
    /// How many steps `steps` holds of each instance.
    per_instance: BTreeMap<String, usize>,
    /// Whether routine steps are hidden.
    hide_routine: bool,
    /// How many shown steps the pane is scrolled back from the newest (0: it follows
    /// the newest).
    scroll: usize,
    /// How many steps the pane shows at once (the view's height, for paging).
    page: usize,
    focus: Focus,
    selected: usize,
    /// The last reply to a command, or an error.
    pub status: String,
    /// Monitoring events heard that were dropped: over `limits::EVENT`, or not a
    /// monitoring event.
    pub dropped_events: u64,
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

/// Why the selected row cannot be commanded ([`Board::command_target`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NoTarget {
    /// No row is selected.
    #[error("no component selected")]
    NoneSelected,
    /// The row's node is lost: a command could only time out.
    #[error("node `{node}` is lost: no command sent to `{address}`")]
    Lost {
        /// The node.
        node: String,
        /// The component's address.
        address: String,
    },
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
        rows.sort_by_cached_key(order);
        self.rows = rows;
        self.selected = self.selected.min(self.rows.len().saturating_sub(1));
    }

    /// A monitoring event of the component at `node/path`: a supervision or
    /// adaptation step goes to the steps pane (newest last); other events are read
    /// at the next refresh.
    pub fn step(&mut self, address: &str, event: &MonitorEvent, at: &str) {
        let (whose, routine) = match event {
            MonitorEvent::Supervision(step) => (
                format!("{address}:{}", step.instance),
                step.step.is_routine(),
            ),
            MonitorEvent::Adaptation(step) => (format!("{address}:{}", step.component), false),
            _ => return,
        };
        self.push(StepLine {
            whose,
            routine,
            text: format!("{at} {address}: {}", describe(event)),
        });
    }

    /// The supervision steps the compounds' monitoring ports still hold
    /// (`Monitor::supervision`, their last steps), into the steps pane: what happened
    /// before `top` started watching (`--once` shows only these).
    pub fn seed_history(&mut self) {
        let history: Vec<(String, Supervision)> = self
            .rows
            .iter()
            .flat_map(|row| {
                let address = row.address();
                row.monitor
                    .supervision
                    .iter()
                    .map(move |step| (address.clone(), step.clone()))
            })
            .collect();
        for (address, step) in history {
            self.push(StepLine {
                whose: format!("{address}:{}", step.instance),
                routine: step.step.is_routine(),
                text: format!("earlier {address}: supervision: {step}"),
            });
        }
    }

    /// Keep `line`, the newest: the oldest of its instance goes beyond
    /// [`STEPS_PER_INSTANCE`], the oldest of all beyond [`STEPS_KEPT`]. A pane
    /// scrolled back stays on the steps it shows.
    fn push(&mut self, line: StepLine) {
        let count = self.per_instance.entry(line.whose.clone()).or_default();
        if *count >= STEPS_PER_INSTANCE {
            *count -= 1;
            if let Some(oldest) = self.steps.iter().position(|s| s.whose == line.whose) {
                self.steps.remove(oldest);
            }
        }
        if self.steps.len() >= STEPS_KEPT
            && let Some(oldest) = self.steps.pop_front()
            && let Some(count) = self.per_instance.get_mut(&oldest.whose)
        {
            *count -= 1;
            if *count == 0 {
                self.per_instance.remove(&oldest.whose);
            }
        }
        *self.per_instance.entry(line.whose.clone()).or_default() += 1;
        if self.scroll > 0 && self.shows(&line) {
            self.scroll += 1;
        }
        self.steps.push_back(line);
        self.scroll = self.scroll.min(self.max_scroll());
    }

    fn shows(&self, line: &StepLine) -> bool {
        !(self.hide_routine && line.routine)
    }

    /// The steps shown (routine ones hidden if asked), oldest first.
    pub fn steps(&self) -> impl DoubleEndedIterator<Item = &str> {
        self.steps
            .iter()
            .filter(|line| self.shows(line))
            .map(|line| line.text.as_str())
    }

    /// The steps the pane shows now, `rows` at most: the newest, or those it is
    /// scrolled back to; oldest first.
    pub fn steps_window(&self, rows: usize) -> Vec<&str> {
        let shown: Vec<&str> = self.steps().collect();
        let end = shown.len().saturating_sub(self.scroll);
        shown[end.saturating_sub(rows)..end].to_vec()
    }

    /// How many shown steps are newer than the pane shows (0: it follows the newest).
    pub fn scrolled(&self) -> usize {
        self.scroll
    }

    /// How many steps the pane shows at once (the view says, from the screen's size):
    /// the step of a page, and how far back it scrolls.
    pub fn set_page(&mut self, rows: usize) {
        self.page = rows;
        self.scroll = self.scroll.min(self.max_scroll());
    }

    /// How far back the pane scrolls: until its first row is the oldest step shown.
    fn max_scroll(&self) -> usize {
        self.steps().count().saturating_sub(self.page.max(1))
    }

    /// Scroll the steps pane `back` steps towards the oldest (negative: towards the
    /// newest), within what it holds.
    pub fn scroll_steps(&mut self, back: isize) {
        self.scroll = self
            .scroll
            .saturating_add_signed(back)
            .min(self.max_scroll());
    }

    /// Hide routine steps (`commanded`, `retry failed`), or show them again; the pane
    /// goes back to the newest.
    pub fn toggle_routine(&mut self) {
        self.hide_routine = !self.hide_routine;
        self.scroll = 0;
    }

    /// Whether routine steps are hidden.
    pub fn hides_routine(&self) -> bool {
        self.hide_routine
    }

    /// Which pane the arrow keys move.
    pub fn focus(&self) -> Focus {
        self.focus
    }

    /// The arrow keys move the other pane.
    pub fn toggle_focus(&mut self) {
        self.focus = match self.focus {
            Focus::Components => Focus::Steps,
            Focus::Steps => Focus::Components,
        };
    }

    /// An arrow key, `delta` rows down (negative: up), on the pane in focus: the
    /// selection moves, or the steps pane scrolls (up is older).
    pub fn navigate(&mut self, delta: isize) {
        match self.focus {
            Focus::Components => self.select(delta),
            Focus::Steps => self.scroll_steps(-delta),
        }
    }

    /// A page of rows down (negative: up) on the pane in focus.
    pub fn navigate_page(&mut self, pages: isize) {
        let rows = match self.focus {
            Focus::Components => 10,
            Focus::Steps => self.page.max(1),
        };
        self.navigate(pages.saturating_mul(isize::try_from(rows).unwrap_or(isize::MAX)));
    }

    /// Home (`last` false) or end: the first or last row, or the oldest or newest
    /// step.
    pub fn navigate_to(&mut self, last: bool) {
        match (self.focus, last) {
            (Focus::Components, false) => self.selected = 0,
            (Focus::Components, true) => self.selected = self.rows.len().saturating_sub(1),
            (Focus::Steps, false) => self.scroll = self.max_scroll(),
            (Focus::Steps, true) => self.scroll = 0,
        }
    }

    /// The rows, by node and path (an execution group's members together, in the
    /// order they run).
    pub fn rows(&self) -> &[Row] {
        &self.rows
    }

    /// The execution groups of the live rows, each once, in the rows' order, with
    /// the figures of its member heard last.
    pub fn groups(&self) -> Vec<GroupLine> {
        let mut lines: Vec<GroupLine> = Vec::new();
        for row in self.rows.iter().filter(|row| !row.lost) {
            let Some(status) = &row.monitor.group else {
                continue;
            };
            let within = row.path.rsplit_once('.').map_or("", |(w, _)| w).to_owned();
            let line = GroupLine {
                node: row.node.clone(),
                within,
                status: status.clone(),
            };
            match lines.iter_mut().find(|l| {
                (&l.node, &l.within, &l.status.name) == (&line.node, &line.within, &status.name)
            }) {
                Some(seen) if seen.status.cycles < status.cycles => *seen = line,
                Some(_) => {}
                None => lines.push(line),
            }
        }
        lines
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
    pub fn command_target(&self) -> Result<String, NoTarget> {
        match self.selected_row() {
            None => Err(NoTarget::NoneSelected),
            Some(row) if row.lost => Err(NoTarget::Lost {
                node: row.node.clone(),
                address: row.address(),
            }),
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
    use coolbot::Step;

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
        let lost = board.command_target().unwrap_err();
        assert_eq!(
            lost,
            NoTarget::Lost {
                node: "b".to_owned(),
                address: "b/y".to_owned()
            }
        );
        assert_eq!(
            lost.to_string(),
            "node `b` is lost: no command sent to `b/y`"
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
            &MonitorEvent::Supervision(Supervision {
                instance: "w".to_owned(),
                step: Step::Failed,
                detail: "boom".to_owned(),
            }),
            "1.5s",
        );
        let steps: Vec<_> = board.steps().collect();
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

    fn supervision(instance: &str, step: Step) -> MonitorEvent {
        MonitorEvent::Supervision(Supervision {
            instance: instance.to_owned(),
            step,
            detail: String::new(),
        })
    }

    fn commanded() -> Step {
        Step::Commanded {
            command: "set max_speed = 0.5".to_owned(),
        }
    }

    #[test]
    fn each_instance_keeps_its_newest_steps_whatever_another_sends() {
        let mut board = Board::new();
        let substituted = Step::Substituted {
            by: "spare".to_owned(),
        };
        board.step("r/cell", &supervision("ranges", substituted), "0.0s");
        for n in 0..300 {
            board.step(
                "r/cell",
                &supervision("motion", commanded()),
                &format!("{n}s"),
            );
        }
        let steps: Vec<&str> = board.steps().collect();
        assert_eq!(steps.len(), 1 + STEPS_PER_INSTANCE);
        assert_eq!(
            steps[0],
            "0.0s r/cell: supervision: ranges substituted by spare"
        );
        // The motion's newest, in order.
        assert!(steps[1].starts_with("250s r/cell: supervision: motion commanded"));
        assert!(steps[STEPS_PER_INSTANCE].starts_with("299s "));
        // Another compound's instance of the same name is another instance.
        board.step("r/other", &supervision("motion", Step::Failed), "300s");
        assert_eq!(board.steps().count(), 2 + STEPS_PER_INSTANCE);
    }

    #[test]
    fn routine_steps_are_hidden_on_demand() {
        let mut board = Board::new();
        board.step("r/cell", &supervision("w", Step::Failed), "1s");
        board.step("r/cell", &supervision("w", Step::RetryFailed), "2s");
        board.step("r/cell", &supervision("m", commanded()), "3s");
        board.step("r/cell", &supervision("w", Step::Recovered), "4s");
        assert_eq!(board.steps().count(), 4);
        board.toggle_routine();
        assert!(board.hides_routine());
        let shown: Vec<&str> = board.steps().collect();
        assert_eq!(
            shown,
            [
                "1s r/cell: supervision: w failed",
                "4s r/cell: supervision: w recovered"
            ]
        );
        board.toggle_routine();
        assert_eq!(board.steps().count(), 4);
    }

    #[test]
    fn the_steps_pane_scrolls_and_stays_where_it_was_scrolled() {
        let mut board = Board::new();
        for n in 0..20 {
            board.step("r/c", &supervision("w", Step::Failed), &format!("{n}s"));
        }
        board.set_page(5);
        let first = |board: &Board| {
            board.steps_window(5)[0]
                .split(' ')
                .next()
                .unwrap()
                .to_owned()
        };
        assert_eq!(first(&board), "15s");
        // The keys move the table until the steps pane has the focus.
        board.navigate(-3);
        assert_eq!(board.scrolled(), 0);
        board.toggle_focus();
        assert_eq!(board.focus(), Focus::Steps);
        board.navigate(-3);
        assert_eq!((board.scrolled(), first(&board)), (3, "12s".to_owned()));
        // A new step does not move what is shown.
        board.step("r/c", &supervision("w", Step::Failed), "20s");
        assert_eq!((board.scrolled(), first(&board)), (4, "12s".to_owned()));
        board.navigate_page(-1);
        assert_eq!(first(&board), "7s");
        // No further back than the oldest, no further on than the newest.
        board.navigate_page(-9);
        assert_eq!(first(&board), "0s");
        board.navigate_to(true);
        assert_eq!((board.scrolled(), first(&board)), (0, "16s".to_owned()));
        board.navigate(5);
        assert_eq!(board.scrolled(), 0);
        board.navigate_to(false);
        assert_eq!(first(&board), "0s");
    }
}
