//! The live status table: every component's monitoring port, one row each, plus the
//! variables it publishes, drawn with ratatui ([`render`]); and the one-line form for
//! logs and pipes ([`line()`]).

use std::time::Duration;

use coolbot::adapt::Pressure;
use coolbot::{Monitor, Value};

/// What one row shows: the monitor, its component type and the CPU load since the
/// previous frame.
#[derive(Clone, Debug)]
pub struct Row {
    /// How deep in the hierarchy the component is (0: the top compound).
    pub depth: usize,
    /// The component type (from its spec).
    pub type_name: &'static str,
    /// Its quality levels by name (its timing block's `quality`; empty without).
    pub qualities: &'static [&'static str],
    /// A snapshot of its monitoring port.
    pub monitor: Monitor,
    /// CPU time over wall time since the previous frame (0..1).
    pub load: f64,
}

/// Formats a variable compactly: floats with two decimals, records as `{k:v ...}`.
pub fn value(value: &Value) -> String {
    fn json(v: &serde_json::Value) -> String {
        match v {
            serde_json::Value::Number(n) if n.is_f64() => {
                format!("{:.2}", n.as_f64().unwrap_or(0.0))
            }
            serde_json::Value::Object(fields) => {
                let parts: Vec<String> = fields
                    .iter()
                    .map(|(k, v)| format!("{k}:{}", json(v)))
                    .collect();
                format!("{{{}}}", parts.join(" "))
            }
            serde_json::Value::Array(items) => {
                let parts: Vec<String> = items.iter().map(json).collect();
                format!("[{}]", parts.join(","))
            }
            serde_json::Value::String(s) => s.clone(),
            other => other.to_string(),
        }
    }
    match value {
        Value::Float(x) => format!("{x:.2}"),
        Value::Json(v) => json(v),
        other => json(&other.to_json()),
    }
}

/// A period in milliseconds (`66.7ms`, `50ms`), `-` without one.
pub fn period(period: Option<Duration>) -> String {
    match period {
        Some(p) if !p.is_zero() => {
            let ms = p.as_secs_f64() * 1e3;
            if (ms - ms.round()).abs() < 0.05 {
                format!("{ms:.0}ms")
            } else {
                format!("{ms:.1}ms")
            }
        }
        _ => "-".to_owned(),
    }
}

/// A quality level by name (`full`, `half`), its index when it has no name.
pub fn quality(level: usize, names: &[&str]) -> String {
    names
        .get(level)
        .map_or_else(|| level.to_string(), |name| (*name).to_owned())
}

/// The adaptation columns: the level out of the highest (a compound: the cap its
/// instances may reach) and the verdict; `-` where adaptation is off.
fn adaptation(monitor: &Monitor) -> (String, &'static str) {
    let status = &monitor.adaptation;
    if !status.enabled {
        return ("-".to_owned(), "-");
    }
    let pressure = match status.pressure {
        Pressure::Nominal => "nominal",
        Pressure::Violation => "VIOLATION",
        Pressure::Spare => "spare",
    };
    (format!("{}/{}", status.level, status.max_level), pressure)
}

fn clip(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        text.to_owned()
    } else {
        let mut s: String = text.chars().take(width.saturating_sub(1)).collect();
        s.push('~');
        s
    }
}

/// Joins `items` with two spaces into lines of at most `width` characters (an item
/// longer than that is clipped).
fn wrap(items: &[String], width: usize) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for item in items {
        let item = clip(item, width);
        if !line.is_empty() && line.chars().count() + 2 + item.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push_str("  ");
        }
        line.push_str(&item);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// The column headings of the table.
fn headings() -> String {
    format!(
        "{:<13} {:<16} {:<14} {:<11} {:>7} {:<4} {:>5} {:<9} {:>5} {:>6} {:>6} {:>6}  ERROR",
        "COMPONENT",
        "TYPE",
        "STATE",
        "USER STATE",
        "PERIOD",
        "QUAL",
        "LEVEL",
        "PRESSURE",
        "CPU%",
        "MISSED",
        "OVERRN",
        "OVERFL",
    )
}

/// One row's line: the component's states, timing, adaptation, counters and error.
fn row_line(row: &Row) -> String {
    let m = &row.monitor;
    let (level, pressure) = adaptation(m);
    format!(
        "{:<13} {:<16} {:<14} {:<11} {:>7} {:<4} {:>5} {:<9} {:>5.1} {:>6} {:>6} {:>6}  {}",
        clip(&format!("{}{}", " ".repeat(row.depth), m.name), 13),
        clip(row.type_name, 16),
        m.state.to_string(),
        // The user automaton's state matters only while it can run.
        clip(
            match m.state {
                coolbot::State::Running | coolbot::State::Suspended => {
                    m.user_state.as_deref().unwrap_or("-")
                }
                _ => "-",
            },
            11
        ),
        period(m.period),
        clip(
            &if row.qualities.is_empty() {
                "-".to_owned()
            } else {
                quality(m.quality, row.qualities)
            },
            4
        ),
        level,
        pressure,
        row.load * 100.0,
        m.missed_deadlines,
        m.overruns,
        m.overflows,
        m.error.as_deref().unwrap_or(""),
    )
}

/// The table's lines for a terminal `width` columns wide: the headings, then each
/// component's row and its variables (wrapped to the width, indented by depth).
/// Lines longer than the width are clipped where they are drawn.
pub fn table_lines(rows: &[Row], width: usize) -> Vec<String> {
    let mut lines = vec![headings()];
    for row in rows {
        lines.push(row_line(row));
        let vars: Vec<String> = row
            .monitor
            .variables
            .iter()
            .map(|(name, v)| format!("{name}={}", value(v)))
            .collect();
        let indent = row.depth + 2;
        for line in wrap(&vars, width.saturating_sub(indent).max(20)) {
            lines.push(format!("{}{line}", " ".repeat(indent)));
        }
    }
    lines
}

/// Draws the live view into `frame`, whatever its size: the header line, the table
/// (as many lines as fit), and below it the latest of `log` in an `events` box (when
/// at least one line of it fits). Every line is clipped to the width: nothing wraps,
/// and ratatui redraws every cell that changed, so no character of an earlier frame
/// stays on screen.
pub fn render(frame: &mut ratatui::Frame<'_>, header: &str, rows: &[Row], log: &[String]) {
    use ratatui::layout::{Constraint, Layout};
    use ratatui::style::{Modifier, Style};
    use ratatui::text::Line;
    use ratatui::widgets::{Block, Paragraph};

    let area = frame.area();
    let table = table_lines(rows, usize::from(area.width));
    let table_height = u16::try_from(table.len()).unwrap_or(u16::MAX);
    let [head, body, events] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(table_height),
        Constraint::Min(0),
    ])
    .areas(area);
    frame.render_widget(
        Paragraph::new(header).style(Style::new().add_modifier(Modifier::BOLD)),
        head,
    );
    let lines: Vec<Line<'_>> = table
        .into_iter()
        .enumerate()
        .map(|(i, text)| {
            if i == 0 {
                Line::styled(text, Style::new().add_modifier(Modifier::REVERSED))
            } else {
                Line::raw(text)
            }
        })
        .collect();
    frame.render_widget(Paragraph::new(lines), body);
    if events.height >= 3 {
        let shown = usize::from(events.height - 2);
        let latest = &log[log.len().saturating_sub(shown)..];
        let lines: Vec<Line<'_>> = latest.iter().map(|l| Line::raw(l.as_str())).collect();
        frame.render_widget(
            Paragraph::new(lines).block(Block::bordered().title(" events ")),
            events,
        );
    }
}

/// The terminal while the live view is on it: the alternate screen (the shell's
/// screen comes back as it was when this is dropped), the cursor hidden. Raw mode is
/// not used: Ctrl-C still sends SIGINT, which stops the run cleanly.
pub struct Screen {
    terminal: ratatui::Terminal<ratatui::backend::CrosstermBackend<std::io::Stdout>>,
}

impl Screen {
    /// Takes over the terminal.
    pub fn open() -> std::io::Result<Screen> {
        use ratatui::crossterm::{execute, terminal::EnterAlternateScreen};
        let mut stdout = std::io::stdout();
        execute!(stdout, EnterAlternateScreen)?;
        let mut terminal = ratatui::Terminal::new(ratatui::backend::CrosstermBackend::new(stdout))?;
        terminal.hide_cursor()?;
        terminal.clear()?;
        Ok(Screen { terminal })
    }

    /// Draws a frame ([`render`]); a terminal resized since the last frame is
    /// cleared and drawn whole.
    pub fn draw(&mut self, header: &str, rows: &[Row], log: &[String]) -> std::io::Result<()> {
        self.terminal
            .draw(|frame| render(frame, header, rows, log))
            .map(|_| ())
    }
}

impl Drop for Screen {
    fn drop(&mut self) {
        use ratatui::crossterm::{execute, terminal::LeaveAlternateScreen};
        let _ = self.terminal.show_cursor();
        let _ = execute!(self.terminal.backend_mut(), LeaveAlternateScreen);
    }
}

/// One line for non-terminal output: each component's state and user state, and
/// the adaptation level of those degraded (`@2/4`).
pub fn line(at: Duration, rows: &[Row], extra: &str) -> String {
    let parts: Vec<String> = rows
        .iter()
        .map(|row| {
            let m = &row.monitor;
            let level = if m.adaptation.enabled && m.adaptation.level > 0 {
                format!("@{}/{}", m.adaptation.level, m.adaptation.max_level)
            } else {
                String::new()
            };
            match &m.user_state {
                Some(user) if m.state == coolbot::State::Running => {
                    format!("{}={}/{user}{level}", m.name, m.state)
                }
                _ => format!("{}={}{level}", m.name, m.state),
            }
        })
        .collect();
    format!("[{:6.2}s] {} {extra}", at.as_secs_f64(), parts.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_print_compactly() {
        assert_eq!(value(&Value::Float(0.123_456)), "0.12");
        let pose = Value::Json(serde_json::json!({ "x": 1.0, "y": 2.5, "theta": 0.25 }));
        assert_eq!(value(&pose), "{theta:0.25 x:1.00 y:2.50}");
        assert_eq!(value(&Value::UInt(7)), "7");
    }

    #[test]
    fn variables_wrap_at_the_width() {
        let items: Vec<String> = ["aaaa", "bbbb", "cccc"].map(String::from).to_vec();
        assert_eq!(wrap(&items, 10), ["aaaa  bbbb", "cccc"]);
        assert_eq!(wrap(&items, 100), ["aaaa  bbbb  cccc"]);
        assert_eq!(wrap(&[], 10), Vec::<String>::new());
    }

    #[test]
    fn periods_and_qualities_print_for_people() {
        assert_eq!(period(Some(Duration::from_millis(50))), "50ms");
        assert_eq!(period(Some(Duration::from_micros(66_667))), "66.7ms");
        assert_eq!(period(None), "-");
        assert_eq!(quality(1, &["full", "half"]), "half");
        assert_eq!(quality(3, &["full", "half"]), "3");
    }

    fn monitor(name: &str, state: coolbot::State, user: &str, vars: &[(&str, Value)]) -> Monitor {
        Monitor {
            name: name.to_owned(),
            state,
            user_state: Some(user.to_owned()),
            result: coolbot::TaskResult::None,
            error: None,
            variables: vars
                .iter()
                .map(|(n, v)| ((*n).to_owned(), v.clone()))
                .collect(),
            cpu_time: Duration::ZERO,
            elapsed_time: Duration::ZERO,
            missed_deadlines: 0,
            overruns: 0,
            overflows: 0,
            port_overflows: Vec::new(),
            quality: 0,
            period: None,
            nominal_period: None,
            max_response: None,
            priority: 0,
            os_priority: coolbot::OsPriority::Inherited,
            dropped_events: 0,
            supervision: Vec::new(),
            supervision_steps: 0,
            adaptation: coolbot::AdaptStatus::default(),
            response: coolbot::ResponseTimes::default(),
            group: None,
        }
    }

    /// The robot as the table shows it after a fault: fixed values.
    fn rows() -> Vec<Row> {
        use coolbot::State::{Running, RunningError};
        let mut ranges = monitor(
            "ranges",
            RunningError,
            "streaming",
            &[("scans", Value::UInt(20))],
        );
        ranges.error = Some(
            "panic in state `streaming` (Periodic section): sensor driver crashed: the ir/us board reset"
                .to_owned(),
        );
        ranges.period = Some(Duration::from_millis(50));
        let mut motion = monitor(
            "motion",
            Running,
            "moving",
            &[
                ("max_speed", Value::Float(0.25)),
                (
                    "odometry",
                    Value::Json(serde_json::json!({"x": 1.5, "y": 2.0, "theta": 0.5})),
                ),
                ("distance", Value::Float(1.234)),
                ("halts", Value::UInt(1)),
            ],
        );
        motion.period = Some(Duration::from_millis(20));
        motion.missed_deadlines = 3;
        let row = |depth, type_name, monitor, load| Row {
            depth,
            type_name,
            qualities: if type_name == "RangeServer" {
                &["full", "half"]
            } else {
                &[]
            },
            monitor,
            load,
        };
        vec![
            row(
                0,
                "Robot",
                monitor("robot", Running, "supervising", &[]),
                0.001,
            ),
            row(
                1,
                "MobileBase",
                monitor(
                    "base",
                    Running,
                    "degraded",
                    &[
                        ("mode", Value::Str("Degraded".into())),
                        ("faults", Value::UInt(1)),
                    ],
                ),
                0.002,
            ),
            row(2, "MotionController", motion, 0.031),
            row(2, "RangeServer", ranges, 0.0),
            row(
                1,
                "Wanderer",
                monitor("wanderer", Running, "wandering", &[]),
                0.004,
            ),
        ]
    }

    /// What a terminal of `width` by `height` shows after one frame.
    fn screen(width: u16, height: u16) -> String {
        let backend = ratatui::backend::TestBackend::new(width, height);
        let mut terminal = ratatui::Terminal::new(backend).unwrap();
        let log: Vec<String> = (1..=20)
            .map(|i| format!("{:6.2}s base: event number {i}", f64::from(i) * 0.25))
            .collect();
        terminal
            .draw(|frame| {
                render(
                    frame,
                    "CoolBOT mobile base   t=  3.0s/10s   base supervisor: degraded (mode Degraded)   pose (1.50, 2.00, 29 deg)",
                    &rows(),
                    &log,
                );
            })
            .unwrap();
        let buffer = terminal.backend().buffer();
        let mut text = String::new();
        for y in 0..height {
            let line: String = (0..width)
                .map(|x| buffer[(x, y)].symbol().to_owned())
                .collect();
            text.push_str(line.trim_end());
            text.push('\n');
        }
        text
    }

    #[test]
    fn the_live_view_fits_any_terminal() {
        for (width, height) in [(160, 45), (100, 30), (80, 24), (40, 12), (20, 4)] {
            let shown = screen(width, height);
            assert_eq!(shown.lines().count(), usize::from(height));
            insta::assert_snapshot!(format!("live_{width}x{height}"), shown);
        }
    }

    #[test]
    fn long_cells_are_clipped() {
        assert_eq!(clip("abcdef", 4), "abc~");
        assert_eq!(clip("abc", 4), "abc");
    }
}
