//! CDR (`coolbot::cdr`, what ROS 2 topics and rosbag2 bags carry) against postcard, for
//! a 720-beam `sensor_msgs/msg/LaserScan` (a hand-written struct with the `.msg`'s
//! fields in order, as coolc generates it): encode and decode, each in one run, and
//! their ratio. No goal: the figure says what speaking ROS 2 costs per message.
//!
//! `cargo bench -p coolbot --bench cdr` (add `-- --quick` for a smoke run).

use std::hint::black_box;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Header {
    stamp: Time,
    frame_id: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct LaserScan {
    header: Header,
    angle_min: f32,
    angle_max: f32,
    angle_increment: f32,
    time_increment: f32,
    scan_time: f32,
    range_min: f32,
    range_max: f32,
    ranges: Vec<f32>,
    intensities: Vec<f32>,
}

fn scan() -> LaserScan {
    LaserScan {
        header: Header {
            stamp: Time {
                sec: 1_700_000_000,
                nanosec: 123_456_789,
            },
            frame_id: "laser".into(),
        },
        angle_min: -std::f32::consts::PI,
        angle_max: std::f32::consts::PI,
        angle_increment: std::f32::consts::TAU / 720.0,
        time_increment: 1e-4,
        scan_time: 0.1,
        range_min: 0.05,
        range_max: 30.0,
        ranges: (0..720_u16).map(|i| 1.0 + f32::from(i) * 0.01).collect(),
        intensities: (0..720_u16).map(f32::from).collect(),
    }
}

/// Median time per call of `f` over `rounds` rounds of `per_round` calls.
fn time(rounds: usize, per_round: u32, mut f: impl FnMut()) -> Duration {
    let mut samples: Vec<Duration> = (0..rounds)
        .map(|_| {
            let started = Instant::now();
            for _ in 0..per_round {
                f();
            }
            started.elapsed() / per_round
        })
        .collect();
    samples.sort();
    samples[samples.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|arg| arg == "--quick");
    let (rounds, per_round) = if quick { (11, 200) } else { (51, 2000) };
    let value = scan();
    let cdr = coolbot::cdr::to_vec(&value).expect("encodes");
    let post = postcard::to_allocvec(&value).expect("encodes");
    assert_eq!(coolbot::cdr::from_slice::<LaserScan>(&cdr).unwrap(), value);
    assert_eq!(postcard::from_bytes::<LaserScan>(&post).unwrap(), value);

    let cdr_encode = time(rounds, per_round, || {
        black_box(coolbot::cdr::to_vec(black_box(&value)).unwrap());
    });
    let post_encode = time(rounds, per_round, || {
        black_box(postcard::to_allocvec(black_box(&value)).unwrap());
    });
    let cdr_decode = time(rounds, per_round, || {
        black_box(coolbot::cdr::from_slice::<LaserScan>(black_box(&cdr)).unwrap());
    });
    let post_decode = time(rounds, per_round, || {
        black_box(postcard::from_bytes::<LaserScan>(black_box(&post)).unwrap());
    });
    let micros = |d: Duration| d.as_secs_f64() * 1e6;
    let ratio = |a: Duration, b: Duration| a.as_secs_f64() / b.as_secs_f64();
    println!(
        "LaserScan, 720 beams: CDR {} bytes, postcard {} bytes",
        cdr.len(),
        post.len()
    );
    println!(
        "encode  CDR {:8.2} us  postcard {:8.2} us  ratio {:.2}x",
        micros(cdr_encode),
        micros(post_encode),
        ratio(cdr_encode, post_encode)
    );
    println!(
        "decode  CDR {:8.2} us  postcard {:8.2} us  ratio {:.2}x",
        micros(cdr_decode),
        micros(post_decode),
        ratio(cdr_decode, post_decode)
    );
}
