//! How `coolctl top` draws a [`Board`]: the component table (each node's tree,
//! lost nodes greyed, the thread each component runs on), the execution groups'
//! pane (each group's members in order and its cycles; only when there is a group),
//! the steps pane (supervision and adaptation steps, newest at
//! the bottom unless scrolled back; its title says what is hidden or below), and a
//! status line (the last reply, or the keys of the pane in focus). Every frame is
//! drawn whole by ratatui, so nothing of an earlier frame stays on screen, at any
//! size.

use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Cell, Paragraph, Row as TableRow, Table, TableState};

use super::model::{Board, Focus, Row};

/// The keys of the pane in focus, shown when there is no reply to show.
pub fn help(board: &Board) -> String {
    let routine = if board.hides_routine() {
        "f show routine"
    } else {
        "f hide routine"
    };
    match board.focus() {
        Focus::Components => format!(
            "up/down select  tab steps  {routine}  s suspend  r run  R restart  v set variable  q quit"
        ),
        Focus::Steps => format!(
            "up/down scroll steps  home/end oldest/newest  tab components  {routine}  q quit"
        ),
    }
}

/// The layout of a screen: the table, the steps pane, the status line.
fn areas(area: Rect) -> [Rect; 3] {
    let steps_height = (area.height / 3).clamp(3, 12);
    Layout::vertical([
        Constraint::Min(3),
        Constraint::Length(steps_height),
        Constraint::Length(1),
    ])
    .areas(area)
}

/// How many steps the steps pane shows on a screen of `width` x `height`.
pub fn steps_rows(width: u16, height: u16) -> usize {
    let [_, steps, _] = areas(Rect::new(0, 0, width, height));
    usize::from(steps.height.saturating_sub(2))
}

fn duration(value: Option<std::time::Duration>) -> String {
    match value {
        Some(d) if d.as_secs() >= 1 => format!("{:.1}s", d.as_secs_f64()),
        Some(d) => format!("{}ms", d.as_millis()),
        None => "-".to_owned(),
    }
}

/// The period in effect, and `/nominal` after it when a command or adaptation moved
/// it from the description's.
fn period(m: &coolbot::Monitor) -> String {
    match m.nominal_period {
        Some(nominal) if m.period != Some(nominal) => {
            format!("{}/{}", duration(m.period), duration(Some(nominal)))
        }
        _ => duration(m.period),
    }
}

fn cells(row: &Row) -> Vec<String> {
    let m = &row.monitor;
    let name = row.path.rsplit('.').next().unwrap_or(&row.path);
    let tree = if row.depth == 0 {
        format!("{}/{name}", row.node)
    } else {
        format!("{}{name}", "  ".repeat(row.depth))
    };
    let state = if row.lost {
        "lost".to_owned()
    } else {
        m.state.to_string()
    };
    vec![
        tree,
        state,
        m.user_state.clone().unwrap_or_else(|| "-".to_owned()),
        period(m),
        m.quality.to_string(),
        format!("{}/{}", m.adaptation.level, m.adaptation.max_level),
        row.cpu_share
            .map_or_else(|| "-".to_owned(), |share| format!("{:.1}", share * 100.0)),
        m.missed_deadlines.to_string(),
        m.overruns.to_string(),
        m.overflows.to_string(),
        m.dropped_events.to_string(),
        m.group
            .as_ref()
            .map_or_else(|| "own".to_owned(), |group| group.name.clone()),
        m.error.clone().unwrap_or_default(),
    ]
}

/// The thread column's index: a group's name, or `own`.
const THREAD: usize = 11;

/// The user state's column.
const USER: usize = 2;

/// The width of column `column`: its longest cell, at least its header, at most
/// `most`.
fn fitted(board: &Board, column: usize, most: usize) -> u16 {
    let longest = board
        .rows()
        .iter()
        .map(|row| cells(row)[column].chars().count())
        .max()
        .unwrap_or(0)
        .clamp(HEADER[column].len(), most.max(HEADER[column].len()));
    u16::try_from(longest).unwrap_or(u16::MAX)
}

const HEADER: [&str; 13] = [
    "COMPONENT",
    "STATE",
    "USER",
    "PERIOD",
    "Q",
    "LVL",
    "CPU%",
    "MISSED",
    "OVERRUN",
    "OVERFL",
    "DROPPED",
    "THREAD",
    "LAST ERROR",
];

/// `columns` without the thread column unless `threads`.
fn shown<T>(threads: bool, columns: Vec<T>) -> impl Iterator<Item = T> {
    columns
        .into_iter()
        .enumerate()
        .filter(move |(index, _)| threads || *index != THREAD)
        .map(|(_, column)| column)
}

/// Draw `board` on the whole frame.
pub fn draw(frame: &mut Frame<'_>, board: &Board) {
    let area = frame.area();
    let [table_area, steps_area, status_area] = areas(area);
    // The groups' pane takes the bottom of the table's area, one line a group.
    let groups = board.groups();
    let (table_area, groups_area) = if groups.is_empty() {
        (table_area, None)
    } else {
        let lines = u16::try_from(groups.len()).unwrap_or(u16::MAX);
        let [table, pane] = Layout::vertical([
            Constraint::Min(3),
            Constraint::Length(lines.saturating_add(2)),
        ])
        .areas(table_area);
        (table, Some(pane))
    };
    let focused = |pane: Focus| {
        if board.focus() == pane {
            Style::new().add_modifier(Modifier::BOLD)
        } else {
            Style::new()
        }
    };

    // The thread column only when some component runs in an execution group
    // (otherwise every row's is `own`).
    let threads = board.rows().iter().any(|row| row.monitor.group.is_some());
    let rows = board.rows().iter().map(|row| {
        let style = if row.lost {
            Style::new().add_modifier(Modifier::DIM)
        } else {
            Style::new()
        };
        TableRow::new(shown(threads, cells(row)).map(Cell::from)).style(style)
    });
    // The component column fits the longest name, up to half the screen; the user
    // state and thread columns their longest, up to 16.
    let first = fitted(board, 0, usize::MAX).min(area.width / 2);
    let (user, thread) = (fitted(board, USER, 16), fitted(board, THREAD, 16));
    let widths: Vec<Constraint> = shown(
        threads,
        vec![
            Constraint::Length(first),
            // The longest state: `starting_error`.
            Constraint::Length(14),
            Constraint::Length(user),
            Constraint::Length(10),
            Constraint::Length(2),
            Constraint::Length(4),
            Constraint::Length(5),
            Constraint::Length(6),
            Constraint::Length(7),
            Constraint::Length(6),
            Constraint::Length(7),
            Constraint::Length(thread),
            Constraint::Fill(1),
        ],
    )
    .collect();
    let table = Table::new(rows, widths)
        .header(
            TableRow::new(shown(threads, HEADER.to_vec()))
                .style(Style::new().add_modifier(Modifier::BOLD)),
        )
        .row_highlight_style(Style::new().add_modifier(Modifier::REVERSED))
        .block(
            Block::bordered()
                .title(" coolctl top: components ")
                .border_style(focused(Focus::Components)),
        );
    let mut state = TableState::new().with_selected(Some(board.selected()));
    frame.render_stateful_widget(table, table_area, &mut state);
    if board.rows().is_empty() {
        let inner = Block::bordered().inner(table_area);
        let [_, line] =
            Layout::vertical([Constraint::Length(1), Constraint::Length(1)]).areas(inner);
        frame.render_widget(
            Paragraph::new(
                "no CoolBOT node answered (yet): start one with --node, or name it with --connect",
            ),
            line,
        );
    }

    if let Some(pane) = groups_area {
        let lines: Vec<Line<'_>> = groups
            .iter()
            .map(|group| Line::from(group.to_string()))
            .collect();
        frame.render_widget(
            Paragraph::new(lines).block(Block::bordered().title(" execution groups ")),
            pane,
        );
    }

    let shown = usize::from(steps_area.height.saturating_sub(2));
    let steps: Vec<Line<'_>> = board
        .steps_window(shown)
        .into_iter()
        .map(Line::from)
        .collect();
    let mut title = " supervision and adaptation steps".to_owned();
    if board.hides_routine() {
        title.push_str(", routine hidden");
    }
    if board.scrolled() > 0 {
        title.push_str(&format!(", {} newer below", board.scrolled()));
    }
    title.push(' ');
    frame.render_widget(
        Paragraph::new(steps).block(
            Block::bordered()
                .title(title)
                .border_style(focused(Focus::Steps)),
        ),
        steps_area,
    );
    let status = if board.status.is_empty() {
        help(board)
    } else {
        board.status.clone()
    };
    frame.render_widget(Paragraph::new(status), status_area);
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    #[test]
    fn the_period_shows_its_nominal_only_when_moved_from_it() {
        let mut m = crate::top::model::tests::monitor("motion", 0);
        assert_eq!(m.period, Some(Duration::from_millis(20)));
        // A snapshot from a node that predates `nominal_period`: the period alone.
        assert_eq!(m.nominal_period, None);
        assert_eq!(super::period(&m), "20ms");
        m.nominal_period = Some(Duration::from_millis(20));
        assert_eq!(super::period(&m), "20ms");
        // Adapted (or commanded) to 40 ms: in effect, then the description's.
        m.period = Some(Duration::from_millis(40));
        assert_eq!(super::period(&m), "40ms/20ms");
        m.period = None;
        assert_eq!(super::period(&m), "-/20ms");
    }

    #[test]
    fn the_steps_pane_says_what_it_hides_and_the_help_line_the_keys_of_the_pane_in_focus() {
        use coolbot::{MonitorEvent, Step, Supervision};
        let mut board = crate::top::Board::new();
        let step = |instance: &str, step: Step| {
            MonitorEvent::Supervision(Supervision {
                instance: instance.to_owned(),
                step,
                detail: String::new(),
            })
        };
        board.step("r/cell", &step("w", Step::Failed), "1.0s");
        for n in 2..40 {
            board.step("r/cell", &step("w", Step::RetryFailed), &format!("{n}.0s"));
        }
        let (width, height) = (100, 30);
        board.set_page(super::steps_rows(width, height));
        let screen = crate::top::render(&board, width, height);
        assert!(
            screen.contains("39.0s r/cell: supervision: w retry failed"),
            "{screen}"
        );
        assert!(!screen.contains("w failed"), "{screen}");
        assert!(
            screen.ends_with(
                "up/down select  tab steps  f hide routine  s suspend  r run  R restart  v set variable  q quit\n"
            ),
            "{screen}"
        );
        board.toggle_routine();
        board.toggle_focus();
        let screen = crate::top::render(&board, width, height);
        assert!(
            screen.contains("┌ supervision and adaptation steps, routine hidden ─"),
            "{screen}"
        );
        assert!(
            screen.contains("│1.0s r/cell: supervision: w failed"),
            "{screen}"
        );
        assert!(!screen.contains("retry failed"), "{screen}");
        assert!(
            screen.ends_with(
                "up/down scroll steps  home/end oldest/newest  tab components  f show routine  q quit\n"
            ),
            "{screen}"
        );
        board.toggle_routine();
        board.navigate(-4);
        let screen = crate::top::render(&board, width, height);
        assert!(
            screen.contains("┌ supervision and adaptation steps, 4 newer below ─"),
            "{screen}"
        );
        assert!(
            screen.contains("│35.0s r/cell: supervision: w retry failed"),
            "{screen}"
        );
        assert!(!screen.contains("36.0s"), "{screen}");
    }
}
