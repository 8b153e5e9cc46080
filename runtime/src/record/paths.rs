//! Ports and components found by their paths in a system (`base.motion.pose`).

use super::RecordError;
use crate::handle::Handle;
use crate::port::{ErasedInput, ErasedOutput};
use crate::system::System;

/// The output at `path`.
pub(super) fn find_output(system: &System, path: &str) -> Result<ErasedOutput, RecordError> {
    let (handle, component, port) = find_component(system, path)?;
    handle
        .outputs
        .iter()
        .find(|(name, _)| *name == port)
        .map(|(_, output)| output.clone())
        .ok_or_else(|| RecordError::UnknownPort {
            path: path.to_owned(),
            component: component.to_owned(),
            direction: "output",
            port: port.to_owned(),
            known: known(handle.outputs.iter().map(|(name, _)| *name)),
        })
}

/// The input at `path`.
pub(super) fn find_input(system: &System, path: &str) -> Result<ErasedInput, RecordError> {
    let (handle, component, port) = find_component(system, path)?;
    let inputs = &handle.inputs;
    inputs
        .iter()
        .find(|(name, _)| *name == port)
        .map(|(_, input)| input.clone())
        .ok_or_else(|| RecordError::UnknownPort {
            path: path.to_owned(),
            component: component.to_owned(),
            direction: "input",
            port: port.to_owned(),
            known: known(inputs.iter().map(|(name, _)| *name)),
        })
}

pub(super) fn find_component<'p>(
    system: &System,
    path: &'p str,
) -> Result<(Handle, &'p str, &'p str), RecordError> {
    let Some((component, port)) = path.rsplit_once('.') else {
        return Err(RecordError::BadPath {
            path: path.to_owned(),
        });
    };
    if component.is_empty() || port.is_empty() {
        return Err(RecordError::BadPath {
            path: path.to_owned(),
        });
    }
    let handle = system
        .handle_at(component)
        .ok_or_else(|| RecordError::UnknownComponent {
            path: path.to_owned(),
            component: component.to_owned(),
        })?;
    Ok((handle, component, port))
}

pub(super) fn known<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let names: Vec<&str> = names.collect();
    if names.is_empty() {
        "none".to_owned()
    } else {
        names.join(", ")
    }
}
