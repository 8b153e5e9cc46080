//! `coolctl top`: a live view of every component of every node on the network
//! (`docs/tools.md`, "`coolctl top`"): the component tree with each default and user
//! state, period, quality, adaptation level, CPU share, missed deadlines, overruns,
//! overflows, dropped events and last error, and the thread it runs on (each
//! execution group's members together, the group's cycles below the table); the
//! supervision and adaptation steps as
//! they happen; keys to suspend, run, restart a component or set a controllable
//! variable, with the reply shown. A node that goes away stays on screen, marked
//! lost, until it comes back.
//!
//! `model` holds what is shown (no terminal), `view` draws it with ratatui, `input`
//! maps keys to actions; this module gathers from the network and runs the loop.

mod input;
pub mod model;
pub mod view;

use std::sync::mpsc;
use std::time::{Duration, Instant};

use coolbot::{Chain, Command, Controllable, MonitorEvent};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{self, Event, KeyEventKind};
use zenoh::Wait;

use crate::ControlReply;
use crate::ctl::{Ctl, CtlError, Listed, parse_command};
use crate::keys;

pub use model::{Board, Focus, NoTarget, Row};

/// The nodes alive and their components, gathered once.
fn gather(ctl: &Ctl) -> Result<(Vec<String>, Vec<Listed>), CtlError> {
    Ok((ctl.node_names()?, ctl.components(None)?))
}

/// One board, gathered twice `interval` apart (the CPU shares are over it), with
/// the compounds' recent supervision steps in the steps pane; [`CtlError::NoNode`]
/// when no node is alive.
pub fn board(ctl: &Ctl, interval: Duration) -> Result<(Board, Vec<String>), CtlError> {
    let mut board = Board::new();
    let (alive, listed) = gather(ctl)?;
    board.refresh(&alive, listed, Instant::now());
    std::thread::sleep(interval);
    let (alive, listed) = gather(ctl)?;
    if alive.is_empty() && listed.is_empty() {
        return Err(ctl.no_node());
    }
    board.refresh(&alive, listed, Instant::now());
    board.seed_history();
    Ok((board, alive))
}

/// `coolctl top --once --json`: every node and component now (CPU shares over
/// `interval`), as JSON.
pub fn once_json(ctl: &Ctl, interval: Duration) -> Result<String, CtlError> {
    let (board, alive) = board(ctl, interval)?;
    Ok(serde_json::to_string_pretty(&board.snapshot(&alive)).expect("a snapshot serializes"))
}

/// `board` drawn on a `width` x `height` screen, as text (`coolctl top --once`, and
/// the snapshot tests).
pub fn render(board: &Board, width: u16, height: u16) -> String {
    let mut terminal = Terminal::new(TestBackend::new(width, height)).expect("a test backend");
    terminal
        .draw(|frame| view::draw(frame, board))
        .expect("a test backend draws");
    let buffer = terminal.backend().buffer();
    let mut text = String::new();
    for y in 0..buffer.area.height {
        let line: String = (0..buffer.area.width)
            .map(|x| buffer[(x, y)].symbol())
            .collect();
        text.push_str(line.trim_end());
        text.push('\n');
    }
    text
}

/// A monitoring event as a node publishes it (on `key`, `payload`), into `board`'s
/// steps pane at `at`. One over [`crate::limits::EVENT`] (not decoded) or that is not
/// a monitoring event is dropped, counted ([`Board::dropped_events`]) and said on the
/// status line; one on a key that is no component's is ignored.
pub fn heard(board: &mut Board, key: &str, payload: &zenoh::bytes::ZBytes, at: &str) {
    let Some((node, path)) = keys::parse_component(key) else {
        return;
    };
    let event = crate::limits::EVENT
        .check(|| "a monitoring event".to_owned(), payload.len())
        .map_err(|exceeded| exceeded.to_string())
        .and_then(|()| {
            serde_json::from_slice::<MonitorEvent>(&payload.to_bytes())
                .map_err(|error| format!("a monitoring event that does not decode ({error})"))
        });
    match event {
        Ok(event) => board.step(&format!("{node}/{path}"), &event, at),
        Err(why) => {
            board.dropped_events += 1;
            board.status = format!(
                "{} monitoring event(s) dropped; the last on {node}/{path}: {}",
                board.dropped_events,
                coolbot::ranges::excerpt(&why, coolbot::ranges::REASON_CHARS)
            );
        }
    }
}

/// What answered a command, for the status line.
fn answered(address: &str, what: &str, reply: Result<ControlReply, CtlError>) -> String {
    match reply {
        Ok(ControlReply::Accepted) => format!("{address}: {what}: accepted"),
        Ok(ControlReply::Rejected { reason }) => format!("{address}: {what}: rejected: {reason}"),
        Err(error) => format!("{address}: {what}: {}", Chain(&error)),
    }
}

/// The interactive view, until `q`: gathers every `refresh`, on its own thread, so
/// that keys are answered while a node is slow to answer. [`CtlError::NoTerminal`]
/// when standard output is not a terminal.
pub fn run(ctl: &Ctl, session: &zenoh::Session, refresh: Duration) -> Result<(), CtlError> {
    use std::io::IsTerminal;
    if !std::io::stdout().is_terminal() {
        return Err(CtlError::NoTerminal {
            why: "its standard output is not one",
            source: None,
        });
    }
    let started = Instant::now();
    // Every monitoring event of every component: the steps pane.
    let events = session
        .declare_subscriber(keys::monitor("*", "*"))
        .wait()
        .map_err(CtlError::zenoh("subscribe to the monitoring events"))?;
    let (gathered, gatherings) = mpsc::channel();
    let gatherer = ctl.clone();
    std::thread::spawn(move || {
        loop {
            if gathered.send(gather(&gatherer)).is_err() {
                break;
            }
            std::thread::sleep(refresh);
        }
    });
    let mut board = Board::new();
    let mut prompt: Option<String> = None;
    let mut terminal = ratatui::try_init().map_err(|source| CtlError::NoTerminal {
        why: "it cannot be set up",
        source: Some(source),
    })?;
    let outcome = (|| -> Result<(), CtlError> {
        loop {
            while let Ok(result) = gatherings.try_recv() {
                match result {
                    Ok((alive, listed)) => {
                        let first = board.rows().is_empty();
                        board.refresh(&alive, listed, Instant::now());
                        if first {
                            board.seed_history();
                        }
                    }
                    Err(error) => board.status = format!("gathering: {}", Chain(&error)),
                }
            }
            while let Ok(Some(sample)) = events.try_recv() {
                let at = format!("{:.1}s", started.elapsed().as_secs_f64());
                heard(
                    &mut board,
                    sample.key_expr().as_str(),
                    sample.payload(),
                    &at,
                );
            }
            if let Some(text) = &prompt {
                board.status = format!("set {text}_  (enter: send, esc: cancel)");
            }
            let size = terminal.size()?;
            board.set_page(view::steps_rows(size.width, size.height));
            terminal.draw(|frame| view::draw(frame, &board))?;
            if !event::poll(Duration::from_millis(100))? {
                continue;
            }
            let Event::Key(key) = event::read()? else {
                continue;
            };
            if key.kind != KeyEventKind::Press {
                continue;
            }
            let address = board.command_target();
            if let Some(text) = &mut prompt {
                match input::edit(text, key) {
                    None => {}
                    Some(false) => {
                        prompt = None;
                        board.status.clear();
                    }
                    Some(true) => {
                        let text = prompt.take().unwrap_or_default();
                        board.status = match (&address, parse_command(std::slice::from_ref(&text)))
                        {
                            (Ok(address), Ok(command)) => {
                                answered(address, &text, ctl.command(address, &command))
                            }
                            (Err(why), _) => why.to_string(),
                            (_, Err(error)) => format!("{text}: {}", Chain(&error)),
                        };
                    }
                }
                continue;
            }
            let state = |target: Controllable| Command::SetState(target);
            match (input::action(key), &address) {
                (input::Action::Quit, _) => return Ok(()),
                (input::Action::Select(delta), _) => {
                    board.navigate(delta);
                    board.status.clear();
                }
                (input::Action::Page(pages), _) => {
                    board.navigate_page(pages);
                    board.status.clear();
                }
                (input::Action::End(last), _) => {
                    board.navigate_to(last);
                    board.status.clear();
                }
                (input::Action::Focus, _) => {
                    board.toggle_focus();
                    board.status.clear();
                }
                (input::Action::Routine, _) => {
                    board.toggle_routine();
                    board.status.clear();
                }
                (
                    input::Action::Prompt
                    | input::Action::Suspend
                    | input::Action::Run
                    | input::Action::Restart,
                    Err(why),
                ) => board.status = why.to_string(),
                (input::Action::Prompt, Ok(_)) => prompt = Some(String::new()),
                (input::Action::Suspend, Ok(address)) => {
                    let reply = ctl.command(address, &state(Controllable::Suspended));
                    board.status = answered(address, "suspend", reply);
                }
                (input::Action::Run, Ok(address)) => {
                    let reply = ctl.command(address, &state(Controllable::Running));
                    board.status = answered(address, "run", reply);
                }
                (input::Action::Restart, Ok(address)) => {
                    let reply = match ctl.command(address, &state(Controllable::Ready)) {
                        Ok(ControlReply::Accepted) => {
                            ctl.command(address, &state(Controllable::Running))
                        }
                        other => other,
                    };
                    board.status = answered(address, "restart", reply);
                }
                _ => {}
            }
        }
    })();
    ratatui::restore();
    outcome
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_over_their_limit_or_undecodable_are_dropped_counted_and_said() {
        let mut board = Board::new();
        let key = "coolbot/robot/motion/m";
        let event = serde_json::to_vec(&MonitorEvent::Quality(1)).unwrap();
        heard(&mut board, key, &zenoh::bytes::ZBytes::from(event), "0.1s");
        assert_eq!(board.dropped_events, 0);
        let huge = vec![b' '; crate::limits::EVENT.max + 1];
        heard(&mut board, key, &zenoh::bytes::ZBytes::from(huge), "0.2s");
        assert_eq!(board.dropped_events, 1);
        assert!(
            board
                .status
                .contains("over the limit EVENT = 4194304 bytes"),
            "{}",
            board.status
        );
        heard(
            &mut board,
            key,
            &zenoh::bytes::ZBytes::from(b"{".to_vec()),
            "0.3s",
        );
        assert_eq!(board.dropped_events, 2);
        assert!(
            board
                .status
                .starts_with("2 monitoring event(s) dropped; the last on robot/motion: "),
            "{}",
            board.status
        );
        // Not a component's key: not a monitoring event at all.
        heard(
            &mut board,
            "coolbot/robot",
            &zenoh::bytes::ZBytes::from(b"{".to_vec()),
            "0.4s",
        );
        assert_eq!(board.dropped_events, 2);
    }
}
