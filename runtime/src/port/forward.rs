//! Forwarding: a compound's exported output following the instance output behind
//! it, and recorders' taps.

use super::*;

/// A compound's exported data output as a sink of the instance output it follows.
pub(super) struct DataForward<T> {
    pub(super) to: Arc<DataOutInner<T>>,
}

impl<T: Packet> Deliver<T> for DataForward<T> {
    fn deliver(&self, packet: Parcel<T>) {
        dispatch(&self.to.sinks.read(), packet);
    }

    fn answers(&self, id: usize) -> bool {
        self.to
            .sinks
            .read()
            .iter()
            .any(|sink| sink.input_id == id || sink.target.answers(id))
    }

    fn deliver_answer(&self, packet: Parcel<T>, id: usize) {
        dispatch_answer(&self.to.sinks.read(), packet, id);
    }

    fn lost(&self, count: u64) {
        for sink in self.to.sinks.read().iter() {
            sink.target.lost(count);
        }
    }

    fn would_wait(&self) -> bool {
        would_wait(&self.to.sinks.read())
    }
}

/// A compound's exported poster output as a tap of the instance output it follows.
pub(super) struct PosterForward<T> {
    pub(super) to: PosterOut<T>,
}

impl<T: Packet> Deliver<T> for PosterForward<T> {
    fn deliver(&self, packet: Parcel<T>) {
        self.to.post(packet.into_owned());
    }
}

/// Pass every packet, post or event `from` produces on to `to` (a compound's exported
/// output following the instance behind it), synchronously on the producer's thread,
/// and the pull requests `to` receives back to `from`. Data packets are not copied
/// for this (the exported output is one more sink of `from`, sharing packets as any
/// sink does); a post is copied once into `to`'s slot. Returns the forwarding's id
/// for [`unforward`], or `None` if the two are not of the same kind and packet type.
pub(crate) fn forward(from: &ErasedOutput, to: &ErasedOutput) -> Option<usize> {
    if from.kind != to.kind || from.type_id != to.type_id {
        return None;
    }
    let id = next_port_id();
    match to.kind {
        OutKind::Tick => {
            let out = output_as::<TickOutInner>(from)?;
            let target = output_as::<TickOutInner>(to)?;
            update_list(&out.targets, |targets| {
                targets.push(TickTarget::Forward { id, to: target })
            });
        }
        OutKind::Data | OutKind::Poster => {
            // The typed half: `to` knows its packet type.
            if !to.end.forward_from(to, from, id) {
                return None;
            }
        }
    }
    to.core.set_route(PullRoute::Output(Arc::clone(&from.core)));
    Some(id)
}

/// Stop a forwarding made by [`forward`], or remove a tap [`tap_data`] added.
pub(crate) fn unforward(from: &ErasedOutput, id: usize) {
    from.end.remove_sink(id);
}

/// Deliver every packet `from` sends (a data output) or posts (a poster output) to
/// `tap` as well (a recorder's tap), on the producer's thread: the tap is one more
/// sink (sharing a packet it gets with the other sinks, see [`shares`]). Returns the
/// tap's id for [`unforward`], or `None` if `from` is neither a data nor a poster
/// output of `T`. A tap is no connection: `System::connections` does not list it.
pub(crate) fn tap_data<T: Packet>(from: &ErasedOutput, tap: Arc<dyn Deliver<T>>) -> Option<usize> {
    let id = next_port_id();
    let sink = Sink {
        input_id: id,
        target: tap,
    };
    if let Some(out) = output_as::<DataOutInner<T>>(from) {
        out.sinks.update(&out.core, |sinks| sinks.push(sink));
    } else {
        output_as::<PosterOutInner<T>>(from)?.add_tap(sink);
    }
    Some(id)
}
