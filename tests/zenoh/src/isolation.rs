//! `CameraRig` (`cool/isolation.cool`): a `NativeDriver` in a process of its own (the
//! node `drivers`, served by `drivers-under-test`) with a local spare. The driver's
//! behaviour stands for a native library: told to crash, it makes a real segmentation
//! fault, which the runtime cannot catch and which ends its process.

use coolbot::SectionResult;
use coolbot_zenoh::agent::Registry;

use crate::generated::{camera_rig, native_driver};

/// `NativeDriver`'s behaviour: counts its frames; the period after `crash` is set
/// writes through a null pointer.
pub struct Native;

impl native_driver::Behavior for Native {
    fn streaming_periodic(&mut self, cx: &mut native_driver::Cx<'_>) -> SectionResult {
        if cx.vars.crash {
            segfault();
        }
        cx.vars.frames += 1;
        Ok(())
    }
}

/// What a bug in a camera SDK or a serial driver written in C does: a write through a
/// null pointer. The process gets SIGSEGV, which no Rust code catches, and dies of it.
#[allow(unsafe_code)]
fn segfault() {
    // SAFETY: none, on purpose: this write is the fault the tests need. Address 0 is
    // never mapped, and a volatile write is neither optimised away nor checked.
    unsafe { std::ptr::null_mut::<u64>().write_volatile(1) };
}

/// The rig's supervisor: nothing of its own.
pub struct Quiet;

impl camera_rig::Supervisor for Quiet {}

/// The rig's parts: two `Native` drivers.
pub struct Parts;

impl camera_rig::Parts for Parts {
    fn supervisor(&mut self) -> impl camera_rig::Supervisor {
        Quiet
    }
    fn camera(&mut self) -> impl native_driver::Behavior {
        Native
    }
    fn spare(&mut self) -> impl native_driver::Behavior {
        Native
    }
}

/// A registry of a `Native` driver and a camera (`crate::camera`): the drivers
/// process builds them for the robot.
pub fn registry() -> Registry {
    let mut registry = Registry::new();
    native_driver::register(&mut registry, |name| native_driver::component(name, Native));
    crate::camera::register(&mut registry);
    registry
}
