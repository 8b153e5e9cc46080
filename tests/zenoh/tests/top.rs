//! `coolctl top` against nodes started here: the board a node's components make,
//! drawn at several terminal sizes (every frame whole, nothing of an earlier one
//! left), and a node that goes away shown lost. (`coolctl top --once --json` from the
//! real binary: `tests/zenoh/tests/coolctl.rs`.)

use std::time::{Duration, Instant};

use coolbot_zenoh::ctl::Ctl;
use coolbot_zenoh::top::{Board, render};
use coolbot_zenoh_tests::support::{PATIENCE, pair, robot, wait_until};

/// The board once `ctl` sees `count` components.
fn board(ctl: &Ctl, count: usize) -> Board {
    let mut board = Board::new();
    assert!(
        wait_until(PATIENCE, || {
            let (Ok(alive), Ok(listed)) = (ctl.node_names(), ctl.components(None)) else {
                return false;
            };
            let complete = listed.len() == count;
            board.refresh(&alive, listed, Instant::now());
            complete
        }),
        "{} components seen, not {count}",
        board.rows().len()
    );
    board
}

#[test]
fn a_nodes_components_draw_at_every_terminal_size() {
    let (robot_node, station) = pair("top-robot", "top-station");
    let system = robot(&robot_node);
    let ctl = Ctl::new(station.session().clone(), Duration::from_secs(5));
    let board = board(&ctl, 6);
    // Wide enough for every column: the layout is exact, and snapshotted.
    for (width, height) in [(160, 45), (100, 30)] {
        let screen = render(&board, width, height);
        assert_eq!(screen.lines().count(), usize::from(height));
        insta::assert_snapshot!(format!("board_{width}x{height}"), screen);
    }
    // Narrower, the columns share what there is (ratatui's layout solver may share a
    // row that cannot hold them all differently from one run to the next, so these
    // are not snapshotted): every frame still fills the screen, frame and title first.
    for (width, height) in [(80, 24), (40, 12), (20, 4)] {
        let screen = render(&board, width, height);
        assert_eq!(screen.lines().count(), usize::from(height));
        assert!(screen.starts_with("┌ coolctl top"), "{screen}");
        assert!(
            screen
                .lines()
                .all(|line| line.chars().count() <= usize::from(width)),
            "{screen}"
        );
    }
    assert!(system.shutdown().clean());
}

#[test]
fn a_node_that_goes_away_is_shown_lost_and_the_board_goes_on() {
    let (robot_node, station) = pair("lost-robot", "lost-station");
    let system = robot(&robot_node);
    let ctl = Ctl::new(station.session().clone(), Duration::from_secs(5));
    let mut board = board(&ctl, 6);
    assert!(system.shutdown().clean());
    drop(robot_node);
    assert!(
        wait_until(PATIENCE, || ctl
            .node_names()
            .is_ok_and(|names| !names.iter().any(|n| n == "lost-robot"))),
        "the robot's node is still alive"
    );
    let alive = ctl.node_names().unwrap();
    board.refresh(&alive, ctl.components(None).unwrap(), Instant::now());
    assert!(
        board.rows().iter().all(|row| row.lost),
        "{:?}",
        board.rows()
    );
    assert_eq!(board.snapshot(&alive).lost, ["lost-robot"]);
    let screen = render(&board, 100, 20);
    assert!(screen.contains("lost-robot/robot"), "{screen}");
    assert_eq!(screen.matches(" lost ").count(), 6, "{screen}");
}
