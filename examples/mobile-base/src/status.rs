//! The live status table: every component's monitoring port, one row each, plus the
//! variables it publishes; and the one-line form for logs and pipes.

use std::fmt::Write as _;
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

/// The table: a header line, one row per component, then its variables.
pub fn table(header: &str, rows: &[Row], log: &[String]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "{header}");
    let _ = writeln!(
        out,
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
    );
    for row in rows {
        let m = &row.monitor;
        let (level, pressure) = adaptation(m);
        let _ = writeln!(
            out,
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
            clip(m.error.as_deref().unwrap_or(""), 48),
        );
        let vars: Vec<String> = m
            .variables
            .iter()
            .map(|(name, v)| format!("{name}={}", value(v)))
            .collect();
        let indent = " ".repeat(row.depth + 2);
        for line in wrap(&vars, 110) {
            let _ = writeln!(out, "{indent}{line}");
        }
    }
    if !log.is_empty() {
        let _ = writeln!(out, "events:");
        for line in log {
            let _ = writeln!(out, "  {line}");
        }
    }
    out
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

    #[test]
    fn long_cells_are_clipped() {
        assert_eq!(clip("abcdef", 4), "abc~");
        assert_eq!(clip("abc", 4), "abc");
    }
}
