//! `Vision` (`cool/camera.cool`): a `Camera` on the node `drivers` streaming 640 x 480
//! RGB images to a `Detector` in the robot's process, as `benches/camera.rs` runs it.

use coolbot::SectionResult;
use coolbot_zenoh::agent::Registry;

use crate::generated::types::Image;
use crate::generated::{camera, detector, vision};

/// Width of the camera's images, in pixels.
pub const WIDTH: u32 = 640;
/// Height of the camera's images, in pixels.
pub const HEIGHT: u32 = 480;

/// The byte at `index` of image `number`: what the detector checks every byte against.
fn byte(number: u64, index: usize) -> u8 {
    (number as usize).wrapping_add(index) as u8
}

/// `Camera`'s behaviour: each period, the next image, its bytes a pattern of its
/// number (the work of a driver that fills a frame), written in a loan of the node's
/// pool of shared memory (`coolbot::Bytes::loan`: the heap where there is none).
pub struct Streaming;

impl camera::Behavior for Streaming {
    fn streaming_periodic(&mut self, cx: &mut camera::Cx<'_>) -> SectionResult {
        cx.vars.frames += 1;
        let number = cx.vars.frames;
        let mut rgb = coolbot::Bytes::loan((WIDTH * HEIGHT * 3) as usize);
        for (index, value) in rgb.iter_mut().enumerate() {
            *value = byte(number, index);
        }
        cx.outputs.image.send(Image {
            number,
            width: WIDTH,
            height: HEIGHT,
            rgb: rgb.freeze(),
        });
        Ok(())
    }
}

/// `Detector`'s behaviour: reads every byte of each image, its mean brightness, and
/// counts the images whose bytes are not the camera's pattern and those read in
/// place (in the camera's loan of shared memory).
pub struct Detecting;

impl detector::Behavior for Detecting {
    fn detecting_entry(&mut self, cx: &mut detector::Cx<'_>) -> SectionResult {
        for image in cx.inputs.image.drain() {
            let mut sum = 0u64;
            let mut intact = image.rgb.len() == (image.width * image.height * 3) as usize;
            for (index, value) in image.rgb.iter().enumerate() {
                sum += u64::from(*value);
                intact &= *value == byte(image.number, index);
            }
            cx.vars.seen += 1;
            if image.rgb.is_lent() {
                cx.vars.lent += 1;
            }
            if !intact {
                cx.vars.bad += 1;
            }
            cx.vars.brightness = sum / image.rgb.len().max(1) as u64;
        }
        Ok(())
    }
}

/// `Vision`'s supervisor: nothing of its own.
pub struct Watching;

impl vision::Supervisor for Watching {}

/// `Vision`'s parts.
pub struct Parts;

impl vision::Parts for Parts {
    fn supervisor(&mut self) -> impl vision::Supervisor {
        Watching
    }
    fn camera(&mut self) -> impl camera::Behavior {
        Streaming
    }
    fn detector(&mut self) -> impl detector::Behavior {
        Detecting
    }
}

/// Adds `Camera` to `registry`: the drivers process builds it for the robot.
pub fn register(registry: &mut Registry) {
    camera::register(registry, |name| camera::component(name, Streaming));
}
