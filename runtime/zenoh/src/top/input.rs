//! The keys of `coolctl top`, as actions (no terminal here: `top` reads the keys and
//! the tests feed them).

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

/// What a key asks for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    /// Move by this many rows in the pane in focus: the selection, or the steps
    /// pane's scroll (up is older).
    Select(isize),
    /// Move by this many pages in the pane in focus.
    Page(isize),
    /// To the first row or the oldest step (`false`), or the last row or the newest
    /// step (`true`).
    End(bool),
    /// The arrow keys move the other pane.
    Focus,
    /// Hide routine steps (`commanded`, `retry failed`), or show them again.
    Routine,
    /// Command the selected component to `suspended`.
    Suspend,
    /// Command it to `running`.
    Run,
    /// Restart it: `ready`, then `running`.
    Restart,
    /// Start typing `variable=value` for it.
    Prompt,
    /// Leave `top`.
    Quit,
    /// Nothing.
    None,
}

/// The action of `key` outside the prompt.
pub fn action(key: KeyEvent) -> Action {
    match key.code {
        KeyCode::Up | KeyCode::Char('k') => Action::Select(-1),
        KeyCode::Down | KeyCode::Char('j') => Action::Select(1),
        KeyCode::PageUp => Action::Page(-1),
        KeyCode::PageDown => Action::Page(1),
        KeyCode::Home | KeyCode::Char('g') => Action::End(false),
        KeyCode::End | KeyCode::Char('G') => Action::End(true),
        KeyCode::Tab | KeyCode::BackTab => Action::Focus,
        KeyCode::Char('f') => Action::Routine,
        KeyCode::Char('s') => Action::Suspend,
        KeyCode::Char('r') => Action::Run,
        KeyCode::Char('R') => Action::Restart,
        KeyCode::Char('v') => Action::Prompt,
        KeyCode::Char('q') | KeyCode::Esc => Action::Quit,
        KeyCode::Char('c') if key.modifiers.contains(KeyModifiers::CONTROL) => Action::Quit,
        _ => Action::None,
    }
}

/// What a key does to the prompt's text: `Some(true)` submits it, `Some(false)`
/// cancels it, `None` goes on typing.
pub fn edit(text: &mut String, key: KeyEvent) -> Option<bool> {
    match key.code {
        KeyCode::Enter => Some(true),
        KeyCode::Esc => Some(false),
        KeyCode::Backspace => {
            text.pop();
            None
        }
        KeyCode::Char(c) => {
            text.push(c);
            None
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(code: KeyCode) -> KeyEvent {
        KeyEvent::new(code, KeyModifiers::NONE)
    }

    #[test]
    fn keys_map_to_actions_and_the_prompt_edits_its_text() {
        assert_eq!(action(key(KeyCode::Down)), Action::Select(1));
        assert_eq!(action(key(KeyCode::Char('R'))), Action::Restart);
        assert_eq!(action(key(KeyCode::Char('x'))), Action::None);
        assert_eq!(action(key(KeyCode::Tab)), Action::Focus);
        assert_eq!(action(key(KeyCode::Char('f'))), Action::Routine);
        assert_eq!(action(key(KeyCode::PageUp)), Action::Page(-1));
        assert_eq!(action(key(KeyCode::End)), Action::End(true));
        assert_eq!(
            action(KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL)),
            Action::Quit
        );
        let mut text = String::new();
        for c in "speed=0.5x".chars() {
            assert_eq!(edit(&mut text, key(KeyCode::Char(c))), None);
        }
        assert_eq!(edit(&mut text, key(KeyCode::Backspace)), None);
        assert_eq!(text, "speed=0.5");
        assert_eq!(edit(&mut text, key(KeyCode::Enter)), Some(true));
        assert_eq!(edit(&mut text, key(KeyCode::Esc)), Some(false));
    }
}
