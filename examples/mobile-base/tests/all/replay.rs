//! A recording of the robot replayed into one component alone: the motion controller
//! in its generated harness (`generated::motion_controller::Harness`), on a virtual
//! clock, with no thread, fed the range scans the robot recorded
//! (`coolbot::harness::replay`).

use std::sync::Arc;
use std::time::Duration;

use coolbot::harness::replay::Replay;
use coolbot::record::Reader;
use mobile_base::generated::motion_controller::{Harness, UserState};
use mobile_base::generated::types::{DriveMode, RangeScan};
use mobile_base::motion_controller::MotionController;
use mobile_base::world::{Platform, World};
use mobile_base::{Display, Options, RECORDED_PORTS, VirtualTime, sensing};

const PERIOD: Duration = Duration::from_millis(20);

#[test]
fn the_motion_controller_replays_the_scans_of_a_recorded_run_in_its_harness() {
    // A recording made by a run of the robot: its odometry and its scans.
    let dir = std::env::temp_dir().join(format!("mobile-base-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("run.mcap");
    // On a virtual clock, as the recording's stamps then are (`VirtualTime`).
    let summary = mobile_base::run(&Options {
        display: Display::Quiet,
        duration: Duration::from_secs(2),
        record: Some(path.clone()),
        virtual_time: Some(VirtualTime::new()),
        ..Options::default()
    })
    .expect("the robot runs");
    let recorded = summary.recorded.expect("a recording summary");
    let mut scans: Vec<(u64, RangeScan)> = Reader::open(&path)
        .expect("the recording opens")
        .packets::<RangeScan>(RECORDED_PORTS[1])
        .map(|item| {
            let (record, scan) = item.expect("a scan");
            (record.t, scan)
        })
        .collect();
    scans.sort_by_key(|(t, _)| *t);
    assert!(scans.len() > 5, "the run recorded scans: {}", scans.len());

    // The motion controller alone, idle, its `obstacles` input fed the scans at their
    // recorded times.
    let platform = Arc::new(Platform::new(
        World::example(),
        World::example_start(),
        None,
    ));
    let mut motion = Harness::running(MotionController::new(platform)).expect("it starts");
    assert_eq!(motion.user_state(), Some(UserState::Idle));
    let mut replay = Replay::open(&path).expect("the recording opens");
    replay
        .route::<RangeScan>(RECORDED_PORTS[1], motion.inner(), "obstacles")
        .expect("scans feed `obstacles`");
    let replayed = replay.play(motion.inner()).expect("the replay plays");

    // Every recorded scan was delivered; the odometry channel was not routed.
    assert_eq!(replayed.sent[RECORDED_PORTS[1]], scans.len() as u64);
    assert_eq!(replayed.skipped, recorded.ports[0].recorded);
    let (first, last) = replayed.span.expect("packets were played");
    assert_eq!(first, Duration::from_nanos(scans[0].0));
    let played = last - first;
    assert_eq!(motion.inner().elapsed(), played);
    // Idle, the controller publishes its odometry once per period: one pose per
    // period elapsed on the harness clock, exactly.
    let poses = motion.sent_pose().expect("poses");
    assert_eq!(poses.len() as u128, played.as_nanos() / PERIOD.as_nanos());

    // One more period: the drive mode follows the last scan's way ahead.
    motion.advance(PERIOD).expect("one more period");
    let last_scan = &scans[scans.len() - 1].1;
    let near = f64::from(sensing::front(last_scan)) < motion.config().cautious_distance;
    let expected = if near {
        DriveMode::Cautious
    } else {
        DriveMode::Normal
    };
    assert_eq!(motion.vars().mode, expected);
    assert_eq!(motion.sent_pose().expect("poses").len(), 1);
    assert_eq!(motion.state(), coolbot::State::Running);
    let _ = std::fs::remove_dir_all(&dir);
}
