//! A compound's exported ports (`input name = inst.port;`, `output name = inst.port;`):
//! the compound's own port, following the instance port it stands for, or whoever
//! stands for that instance now (a substitute, a redundant group's live members or its
//! merged stream).

use std::sync::Arc;
use std::time::{Duration, Instant};

use super::error::ExportError;
use crate::port::{
    DataOut, ErasedInput, ErasedOutput, FifoIn, InputPort, LastIn, OutputPort, Packet, Parcel,
    PosterIn, PosterOut, PullRoute, TickIn, TickOut, UfifoIn,
};

/// How soon the compound's thread retries passing on packets that an instance's full
/// `Block` fifo could not take (they wait at the compound's exported input).
pub(super) const EXPORT_RETRY: Duration = Duration::from_millis(1);

/// How long a redundant member's `Block` fifo at an exported input may stay full
/// while another member has room before the member is left behind (it stalls the
/// group no longer; what it misses is counted lost at its input, which puts it out of
/// step: `in_step`). Until then the members are fed in step and packets wait at the
/// compound's port.
pub const MEMBER_STALL: Duration = Duration::from_millis(100);

/// An exported port: the compound's own port, following the instance port it stands
/// for (or whoever stands for that instance now).
pub(super) trait Export: Send {
    /// The instance port, as declared (`instance.port`).
    fn target(&self) -> &str;
    /// Inputs: move what arrived at the compound's port on to the instance's, without
    /// waiting: what a full `Block` fifo cannot take now stays at the compound's port
    /// (`now`: the compound's clock).
    fn forward(&mut self, _now: Instant) {}
    /// Inputs: packets stayed at the compound's port at the last `forward` (the
    /// compound's thread retries soon).
    fn held(&self) -> bool {
        false
    }
    /// Whether this is an exported input.
    fn is_input(&self) -> bool;
    /// Inputs: feed the instance inputs `inputs` (one, or every live member of a
    /// redundant group).
    fn follow_inputs(&mut self, _inputs: Vec<ErasedInput>) -> Result<(), ExportError> {
        Err(ExportError::NotAnInput)
    }
    /// Outputs: follow `output` (the instance's output, or a redundant group's merged
    /// stream).
    fn follow_output(&mut self, _output: ErasedOutput) -> Result<(), ExportError> {
        Err(ExportError::NotAnOutput)
    }
}

/// The compound's own end of an exported input of packets `T`, with the relay output
/// that feeds the instance's input.
pub(super) enum Twin<T> {
    Fifo(FifoIn<T>, DataOut<T>),
    Ufifo(UfifoIn<T>, DataOut<T>),
    Last(LastIn<T>, DataOut<T>),
    Poster(PosterIn<T>, PosterOut<T>),
}

impl<T: Packet> Twin<T> {
    /// The compound's input, erased.
    pub(super) fn input(&self) -> ErasedInput {
        match self {
            Twin::Fifo(input, _) => input.erased(),
            Twin::Ufifo(input, _) => input.erased(),
            Twin::Last(input, _) => input.erased(),
            Twin::Poster(input, _) => input.erased(),
        }
    }

    /// The relay, erased.
    pub(super) fn relay(&self) -> ErasedOutput {
        match self {
            Twin::Fifo(_, relay) | Twin::Ufifo(_, relay) | Twin::Last(_, relay) => relay.erased(),
            Twin::Poster(_, relay) => relay.erased(),
        }
    }
}

/// An exported input of packets `T`: what arrives at the compound's port is passed on
/// through a relay output connected to the instance's input (a poster input's post is
/// posted again on a relay poster output).
pub(super) struct InputExport<T> {
    pub(super) target: String,
    pub(super) twin: Twin<T>,
    pub(super) linked: Vec<ErasedInput>,
    /// Since when each input of `linked` has been full while another had room.
    pub(super) full_since: Vec<Option<Instant>>,
    /// Packets stayed at the compound's port at the last `forward`.
    pub(super) held: bool,
}

/// A relay whose pull requests (from the instance's `pull` input) become requests of
/// the compound's input `twin` to its own producers.
pub(super) fn route_pulls(relay: &ErasedOutput, twin: &ErasedInput) {
    relay
        .core
        .set_route(PullRoute::Input(Arc::clone(&twin.core)));
}

/// Connect `relay` to the inputs `new`: one input replacing another moves there with
/// what is queued (a stand-in takes over); otherwise inputs no longer fed are
/// unlinked and new ones linked (a redundant group's live members).
pub(super) fn follow_input(
    relay: &ErasedOutput,
    linked: &mut Vec<ErasedInput>,
    new: Vec<ErasedInput>,
) -> Result<(), ExportError> {
    let mismatch = || ExportError::Mismatch("input");
    if let ([old], [input]) = (linked.as_slice(), new.as_slice()) {
        if old.core.id != input.core.id && !relay.relink(old, input) {
            return Err(mismatch());
        }
        *linked = new;
        return Ok(());
    }
    for input in &new {
        if !linked.iter().any(|l| l.core.id == input.core.id) && !relay.link(input) {
            return Err(mismatch());
        }
    }
    for old in linked.iter() {
        if !new.iter().any(|n| n.core.id == old.core.id) {
            relay.unlink(old);
        }
    }
    *linked = new;
    Ok(())
}

impl<T: Packet> Export for InputExport<T> {
    fn target(&self) -> &str {
        &self.target
    }

    fn forward(&mut self, now: Instant) {
        // A fifo with the `Block` policy would make the compound's thread wait while
        // it is full (its instance may hang): only what it has room for goes now.
        // A redundant group's members (several inputs fed) are fed in step: while
        // one's fifo is full, packets wait at the compound's port. One whose fifo has
        // stayed full for `MEMBER_STALL` while another has room (hung, or not yet
        // seen to fail) holds the others back no longer: it is left out, and what it
        // misses is counted as lost at its input (an overflow, with its
        // `MonitorEvent::Overflow`), which puts it out of step with its group.
        let rooms: Vec<Option<usize>> = self.linked.iter().map(ErasedInput::room).collect();
        let open = rooms.iter().any(|room| *room != Some(0));
        self.full_since.resize(rooms.len(), None);
        for (since, room) in self.full_since.iter_mut().zip(&rooms) {
            *since = match (room, *since) {
                (Some(0), _) if !open => None,
                (Some(0), Some(since)) => Some(since),
                (Some(0), None) => Some(now),
                _ => None,
            };
        }
        let skipped: Vec<usize> = (0..rooms.len())
            .filter(|i| {
                self.full_since[*i]
                    .is_some_and(|since| now.saturating_duration_since(since) >= MEMBER_STALL)
            })
            .collect();
        let mut room = rooms
            .iter()
            .enumerate()
            .filter(|(i, _)| !skipped.contains(i))
            .filter_map(|(_, room)| *room)
            .min()
            .unwrap_or(usize::MAX);
        let relay = self.twin.relay();
        for index in &skipped {
            relay.unlink(&self.linked[*index]);
        }
        let mut moved: u64 = 0;
        // Packets pass on as they were queued: a packet its producer shares with
        // other inputs stays shared (no copy for the hop).
        self.held = match &self.twin {
            Twin::Fifo(input, relay) => {
                while room > 0
                    && let Some(packet) = input.recv_parcel()
                {
                    room -= 1;
                    moved += 1;
                    relay.send_parcel(packet);
                }
                !input.is_empty()
            }
            Twin::Ufifo(input, relay) => {
                while room > 0
                    && let Some(packet) = input.recv_parcel()
                {
                    room -= 1;
                    moved += 1;
                    relay.send_parcel(packet);
                }
                !input.is_empty()
            }
            // (Whether a new packet waits is not known without taking it: held while
            // the instance's input is full.)
            Twin::Last(..) if room == 0 => true,
            Twin::Last(input, relay) => {
                if let Some(packet) = input.take_new_shared() {
                    moved += 1;
                    relay.send_parcel(Parcel::Shared(packet));
                }
                false
            }
            Twin::Poster(input, relay) => {
                if let Some(packet) = input.take_new() {
                    relay.post(packet);
                }
                false
            }
        };
        for index in skipped {
            let member = &self.linked[index];
            member.count_left_behind(moved);
            if !relay.link(member) {
                // (It was linked a moment ago, with the same kind and packet type.)
                tracing::error!(target = %self.target, "an exported input could not link a member's input again");
            }
        }
    }

    fn held(&self) -> bool {
        self.held
    }

    fn is_input(&self) -> bool {
        true
    }

    fn follow_inputs(&mut self, inputs: Vec<ErasedInput>) -> Result<(), ExportError> {
        self.full_since.clear();
        follow_input(&self.twin.relay(), &mut self.linked, inputs)
    }
}

/// An exported tick input.
pub(super) struct TickExport {
    pub(super) target: String,
    pub(super) twin: TickIn,
    pub(super) relay: TickOut,
    pub(super) linked: Vec<ErasedInput>,
}

impl Export for TickExport {
    fn target(&self) -> &str {
        &self.target
    }

    fn forward(&mut self, _now: Instant) {
        for _ in 0..self.twin.take() {
            self.relay.emit();
        }
    }

    fn is_input(&self) -> bool {
        true
    }

    fn follow_inputs(&mut self, inputs: Vec<ErasedInput>) -> Result<(), ExportError> {
        follow_input(&self.relay.erased(), &mut self.linked, inputs)
    }
}

/// An exported output (tick, data or poster): what the instance emits, sends or posts
/// goes out of the compound's port too, synchronously on the instance's thread (no
/// extra hop), and the pull requests the compound's port receives go to the
/// instance's output on behalf of the requesting input (`port::forward`).
pub(super) struct OutputExport {
    pub(super) target: String,
    pub(super) twin: ErasedOutput,
    pub(super) source: Option<(ErasedOutput, usize)>,
}

impl Export for OutputExport {
    fn target(&self) -> &str {
        &self.target
    }

    fn is_input(&self) -> bool {
        false
    }

    fn follow_output(&mut self, new: ErasedOutput) -> Result<(), ExportError> {
        if let Some((old, id)) = &self.source {
            if old.core.id == new.core.id {
                return Ok(());
            }
            crate::port::unforward(old, *id);
        }
        self.source = None;
        let id = crate::port::forward(&new, &self.twin).ok_or(ExportError::Mismatch("output"))?;
        self.source = Some((new, id));
        Ok(())
    }
}
