//! How a packet reaches its inputs: the [`Deliver`] trait every receiving end
//! implements, converters in front of an input, and fan-out to an output's sinks.

use super::*;

/// Something that accepts packets of type `T`: an input end, a converter in front of
/// one, a compound's exported output, or a recorder's tap.
pub(crate) trait Deliver<T>: Send + Sync {
    fn deliver(&self, packet: Parcel<T>);

    /// Whether the pull request of input `id` is answered through this sink (a
    /// compound's exported output whose consumers include that input).
    fn answers(&self, _id: usize) -> bool {
        false
    }

    /// Deliver an answer to the pull request of input `id`, which this sink answers.
    fn deliver_answer(&self, packet: Parcel<T>, _id: usize) {
        self.deliver(packet);
    }

    /// `count` packets meant for this sink will never come (a redundant group's
    /// merged stream could not carry them across a failover): an input counts them
    /// as lost (an overflow, with its `MonitorEvent::Overflow`); a sink passing
    /// packets on passes the count on.
    fn lost(&self, _count: u64) {}

    /// Whether a delivery now would wait for room: this sink is, or passes packets on
    /// to, a full fifo whose policy is `Block`.
    fn would_wait(&self) -> bool {
        false
    }

    /// The doorbell of the component whose input this sink is (None for a sink that
    /// passes packets on).
    fn input_bell(&self) -> Option<Arc<Doorbell>> {
        None
    }
}

/// A converter on a connection, in front of the input end.
pub(super) struct Converted<A, B> {
    pub(super) convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
    pub(super) target: Arc<dyn Deliver<B>>,
}

impl<A: Packet, B: Packet> Deliver<A> for Converted<A, B> {
    fn deliver(&self, packet: Parcel<A>) {
        self.target
            .deliver(Parcel::Owned((self.convert)(packet.get())));
    }

    fn lost(&self, count: u64) {
        self.target.lost(count);
    }

    fn would_wait(&self) -> bool {
        self.target.would_wait()
    }
}

/// One connected input of a data output.
pub(super) struct Sink<T> {
    pub(super) input_id: usize,
    pub(super) target: Arc<dyn Deliver<T>>,
}

impl<T> Clone for Sink<T> {
    fn clone(&self) -> Self {
        Sink {
            input_id: self.input_id,
            target: Arc::clone(&self.target),
        }
    }
}

/// Whether a delivery to `sinks` now would wait for room ([`Deliver::would_wait`]).
pub(super) fn would_wait<T>(sinks: &[Sink<T>]) -> bool {
    sinks.iter().any(|sink| sink.target.would_wait())
}

/// Deliver `packet` to every sink: owned to a single one, shared among several when
/// [`shares`] says so, else copied for each but the last.
#[inline]
pub(super) fn dispatch<T: Packet>(sinks: &[Sink<T>], packet: Parcel<T>) {
    let Some((last, rest)) = sinks.split_last() else {
        return;
    };
    if rest.is_empty() {
        last.target.deliver(packet);
    } else if shares::<T>() {
        let shared = packet.into_shared();
        for sink in rest {
            sink.target.deliver(Parcel::Shared(Arc::clone(&shared)));
        }
        last.target.deliver(Parcel::Shared(shared));
    } else {
        for sink in rest {
            sink.target.deliver(packet.clone());
        }
        last.target.deliver(packet);
    }
}

/// Deliver an answer to input `id`'s pull request to the one sink that leads there
/// (the input itself, or an exported output in front of it). False if none does.
pub(super) fn dispatch_answer<T: Packet>(sinks: &[Sink<T>], packet: Parcel<T>, id: usize) -> bool {
    if let Some(sink) = sinks.iter().find(|sink| sink.input_id == id) {
        sink.target.deliver(packet);
        true
    } else if let Some(sink) = sinks.iter().find(|sink| sink.target.answers(id)) {
        sink.target.deliver_answer(packet, id);
        true
    } else {
        false
    }
}
