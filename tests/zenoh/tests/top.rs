//! `coolctl top` against nodes started here: the board a node's components make,
//! drawn at several terminal sizes (every frame whole, nothing of an earlier one
//! left), a node that goes away shown lost, and the steps pane of a compound whose
//! recovery retries flood it (routine steps hidden, scrolled back to the
//! substitution). (`coolctl top --once --json` from the real binary:
//! `tests/zenoh/tests/coolctl.rs`.)

use std::sync::Arc;
use std::time::{Duration, Instant};

use coolbot::{State, System};
use coolbot_zenoh::agent::Agent;
use coolbot_zenoh::ctl::Ctl;
use coolbot_zenoh::top::{Board, heard, render};
use coolbot_zenoh::{Placer, keys};
use coolbot_zenoh_tests::dying::{Parts, registry};
use coolbot_zenoh_tests::generated::dying_cell;
use coolbot_zenoh_tests::support::{PATIENCE, pair, robot, wait_until};
use zenoh::Wait;

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

#[test]
fn routine_steps_are_hidden_on_demand_and_the_steps_pane_scrolls_back_to_the_substitution() {
    let (station, robot_node) = pair("dying-station", "steps-robot");
    let (station, robot_node) = (Arc::new(station), Arc::new(robot_node));
    let agent = Agent::start(Arc::clone(&station), registry()).expect("agent");
    let _placer = Placer::new(Arc::clone(&robot_node), registry()).install();
    let mut system = System::new();
    let cell = system
        .add(dying_cell::component("cell", Parts).expect("the compound builds"))
        .unwrap();
    system.run_all().unwrap();
    cell.instance("flaky")
        .unwrap()
        .wait_for(|m| m.state == State::Running, PATIENCE)
        .unwrap_or_else(|timeout| panic!("the remote instance runs: {timeout}"));
    robot_node.expose_system(&system).unwrap();
    // What `coolctl top` hears, on the station's session.
    let events = station
        .session()
        .declare_subscriber(keys::monitor("*", "*"))
        .wait()
        .unwrap();
    assert!(
        wait_until(PATIENCE, || station
            .session()
            .get(keys::monitor("steps-robot", "cell"))
            .wait()
            .is_ok_and(|replies| replies.recv().is_ok())),
        "the station hears the robot's cell"
    );

    // The agent goes: the spare stands in, and every retry of the recovery queue
    // (every 200 ms) fails while no agent answers: routine steps, many.
    drop(agent);
    let mut board = Board::new();
    let retries = |board: &Board| board.steps().filter(|s| s.contains("retry failed")).count();
    assert!(
        wait_until(PATIENCE, || {
            while let Ok(Some(sample)) = events.try_recv() {
                heard(
                    &mut board,
                    sample.key_expr().as_str(),
                    sample.payload(),
                    "t",
                );
            }
            retries(&board) >= 12
        }),
        "{:#?}",
        board.steps().collect::<Vec<_>>()
    );
    let substituted = "t steps-robot/cell: supervision: flaky substituted by spare";
    let (width, height) = (120, 24);
    board.set_page(coolbot_zenoh::top::view::steps_rows(width, height));
    // Shown: the newest retries; the substitution scrolled out of the pane.
    let screen = render(&board, width, height);
    assert!(screen.contains("flaky retry failed"), "{screen}");
    assert!(!screen.contains(substituted), "{screen}");
    // Routine steps hidden: the substitution is in the pane again.
    board.toggle_routine();
    let screen = render(&board, width, height);
    assert!(screen.contains(substituted), "{screen}");
    assert!(!screen.contains("retry failed"), "{screen}");
    assert!(screen.contains("routine hidden"), "{screen}");
    // Shown again, the pane scrolls back to it: tab, then home.
    board.toggle_routine();
    board.toggle_focus();
    board.navigate_to(false);
    let screen = render(&board, width, height);
    assert!(screen.contains(substituted), "{screen}");
    assert!(screen.contains("newer below"), "{screen}");
    assert!(screen.contains("up/down scroll steps"), "{screen}");
    let _ = system.shutdown();
}

#[test]
fn an_execution_groups_members_sit_together_with_their_thread_and_the_groups_cycles() {
    use coolbot_zenoh_tests::generated::plain;
    use coolbot_zenoh_tests::support::Quiet;
    let (robot_node, station) = pair("group-robot", "group-station");
    let mut system = System::new();
    for name in ["drive", "logger", "scan"] {
        system.add(plain::component(name, Quiet)).unwrap();
    }
    // Given (and run, nothing connecting them) as `scan, drive`.
    system.group("control", &["scan", "drive"]).unwrap();
    system.run_all().unwrap();
    robot_node.expose_system(&system).unwrap();
    let ctl = Ctl::new(station.session().clone(), Duration::from_secs(5));
    let board = board(&ctl, 3);
    // The members together, in the order they run, where the first by name would be.
    let rows: Vec<(&str, Option<&str>)> = board
        .rows()
        .iter()
        .map(|row| {
            (
                row.path.as_str(),
                row.monitor.group.as_ref().map(|g| g.name.as_str()),
            )
        })
        .collect();
    assert_eq!(
        rows,
        [
            ("scan", Some("control")),
            ("drive", Some("control")),
            ("logger", None)
        ]
    );
    let groups = board.groups();
    assert_eq!(groups.len(), 1, "{groups:?}");
    assert_eq!(groups[0].status.members, ["scan", "drive"]);
    assert!(groups[0].status.cycles > 0, "{groups:?}");
    let screen = render(&board, 160, 20);
    let thread = |name: &str| {
        let line = screen
            .lines()
            .find(|line| line.starts_with(&format!("│group-robot/{name} ")))
            .unwrap_or_else(|| panic!("no row of {name}: {screen}"));
        line.split_whitespace()
            .nth(11)
            .unwrap_or_default()
            .to_owned()
    };
    assert_eq!(
        ["scan", "drive", "logger"].map(thread),
        ["control", "control", "own"]
    );
    assert!(
        screen.contains("│thread control in group-robot: scan > drive; cycle "),
        "{screen}"
    );
    assert!(screen.contains(" 0 overruns in "), "{screen}");
    assert!(system.shutdown().clean());
}
