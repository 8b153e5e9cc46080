//! Filled-in `PanTilt`: posts where it points, moving toward `pan`.

use crate::generated::pan_tilt::*;
use crate::generated::types::PanTiltPose;

/// Where it points now.
#[derive(Debug, Default)]
pub struct PanTilt {
    pan: f64,
}

impl Behavior for PanTilt {
    fn tracking_periodic(&mut self, cx: &mut Cx<'_>) -> coolbot::SectionResult {
        self.pan += (cx.vars.pan - self.pan).clamp(-0.1, 0.1);
        cx.outputs.position.post(PanTiltPose {
            pan: self.pan,
            tilt: 0.0,
        });
        Ok(())
    }
}
