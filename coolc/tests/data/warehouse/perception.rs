//! Filled-in `Perception`: no supervisor sections.

use crate::generated::perception::*;

/// Keeps nothing.
#[derive(Debug, Default)]
pub struct PerceptionSupervisor {}

impl Supervisor for PerceptionSupervisor {}

/// The crate's camera, detectors and pan-tilt unit.
#[derive(Debug, Default)]
pub struct PerceptionParts {}

impl Parts for PerceptionParts {
    fn supervisor(&mut self) -> impl Supervisor {
        PerceptionSupervisor::default()
    }

    fn camera(&mut self) -> impl crate::generated::camera::Behavior {
        crate::camera::Camera::default()
    }

    fn det_a(&mut self) -> impl crate::generated::detector::Behavior {
        crate::detector::Detector::default()
    }

    fn det_b(&mut self) -> impl crate::generated::detector::Behavior {
        crate::detector::Detector::default()
    }

    fn pantilt(&mut self) -> impl crate::generated::pan_tilt::Behavior {
        crate::pan_tilt::PanTilt::default()
    }
}
