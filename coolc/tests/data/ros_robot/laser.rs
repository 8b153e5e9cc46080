//! Filled-in `Laser`: scan `n` is stamped `n`, in the frame `laser`, with the ranges
//! `n + 1 + i / 10` for `i` in `0..8`.

use crate::generated::laser::*;
use crate::generated::types::LaserScan;
use crate::generated::types::ros::builtin_interfaces::Time;
use crate::generated::types::ros::std_msgs::Header;

/// No state of its own.
#[derive(Debug, Default)]
pub struct Laser {}

impl Behavior for Laser {
    fn scanning_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        cx.vars.sent += 1;
        cx.outputs.scan.send(scan(cx.vars.sent));
        Ok(())
    }
}

/// Scan `n`.
pub fn scan(n: u64) -> LaserScan {
    let n = u16::try_from(n).unwrap_or(u16::MAX);
    LaserScan {
        header: Header {
            stamp: Time {
                sec: i32::from(n),
                nanosec: 0,
            },
            frame_id: "laser".into(),
        },
        angle_min: -0.4,
        angle_max: 0.3,
        angle_increment: 0.1,
        range_min: 0.05,
        range_max: 30.0,
        ranges: (0..8u8)
            .map(|i| f32::from(n) + 1.0 + f32::from(i) / 10.0)
            .collect(),
        ..LaserScan::default()
    }
}
