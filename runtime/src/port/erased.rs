//! Type-erased ports, for `PortSet`, `System::connect` and the runner: the
//! connection rules of each kind pair, linking and unlinking.

use super::*;

/// The kind of an input end, erased of its packet type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum InKind {
    Tick,
    Fifo,
    Ufifo,
    Last,
    Poster,
}

impl InKind {
    pub(crate) fn name(self) -> &'static str {
        match self {
            InKind::Tick => "tick",
            InKind::Fifo => "fifo",
            InKind::Ufifo => "ufifo",
            InKind::Last => "last",
            InKind::Poster => "poster",
        }
    }
}

/// The kind of an output end, erased of its packet type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OutKind {
    Tick,
    Data,
    Poster,
}

impl OutKind {
    pub(crate) fn name(self) -> &'static str {
        match self {
            OutKind::Tick => "tick",
            OutKind::Data => "data",
            OutKind::Poster => "poster",
        }
    }
}

/// What the type-erased code (connecting, moving a connection's input end, retiring a
/// component) asks of an input end, implemented by each typed input end. The defaults
/// are those of an input that holds no queue.
pub(crate) trait InputEnd: Any + Send + Sync {
    /// Forget the source of a poster input if it is the output with this id (an
    /// input's source may already be another output's: see `replace_link`).
    fn clear_source(&self, _output: usize) {}

    /// Move what is queued here into `to`, an input of the same kind and packet type:
    /// how many packets (or events) moved.
    fn transfer(&self, _to: &ErasedInput) -> u64 {
        0
    }

    /// Empty the queue (fifo, ufifo): how many packets were in it.
    fn discard(&self) -> u64 {
        0
    }

    /// Room left in a fifo whose policy is `Block` (`None` for every other input: a
    /// delivery to it never waits).
    fn room(&self) -> Option<usize> {
        None
    }

    /// A new, unconnected output that can feed this input (same packet type): a tick
    /// output for a tick input, a poster output for a poster input, a data output
    /// for the others. A harness (`crate::harness`) feeds inputs through these.
    fn feeder(&self) -> ErasedOutput;
}

/// What the type-erased code asks of an output end, implemented by each typed output
/// end. `output` is the erased handle of `self`; `input` has been checked for kind.
pub(crate) trait OutputEnd: Any + Send + Sync {
    /// Connect to `input`: false if it is not of this output's packet type after all.
    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool;

    /// Disconnect from `input`.
    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput);

    /// Move the connection from `old` to `new` in one step, with what is queued.
    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool;

    /// Make this output (`this`, a compound's exported data or poster output) follow
    /// `from`: one more sink or tap of `from`, with id `id`, passing on to this one.
    /// False if `from` is not of this output's kind and packet type.
    fn forward_from(&self, _this: &ErasedOutput, _from: &ErasedOutput, _id: usize) -> bool {
        false
    }

    /// Remove the forwarding or tap with id `id` (nothing if there is none).
    fn remove_sink(&self, id: usize);

    /// A merge of `lanes` outputs like this one (data outputs only).
    fn merge(&self, _lanes: usize) -> Option<Arc<dyn MergeEnd>> {
        None
    }

    /// Keep everything `output` (this end) sends from now on, for a harness
    /// (`crate::harness`): a data or poster output gets a [`Collected`] tap (see
    /// [`tap_data`]), a tick output a tick input of its own. The tap's or input's
    /// id (a pull request on its behalf is answered to it) and the collector.
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)>;
}

/// An input port with its packet type erased (see [`InputPort`]).
#[derive(Clone)]
pub struct ErasedInput {
    pub(crate) kind: InKind,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) core: Arc<InputCore>,
    pub(super) end: Arc<dyn InputEnd>,
}

/// The typed input end behind `input`, if it is an `X`.
pub(super) fn input_as<X: InputEnd>(input: &ErasedInput) -> Option<Arc<X>> {
    let any: Arc<dyn Any + Send + Sync> = input.end.clone();
    any.downcast::<X>().ok()
}

/// The typed output end behind `output`, if it is an `X`.
pub(super) fn output_as<X: OutputEnd>(output: &ErasedOutput) -> Option<Arc<X>> {
    let any: Arc<dyn Any + Send + Sync> = output.end.clone();
    any.downcast::<X>().ok()
}

impl ErasedInput {
    /// How many packets a delivery can add without waiting, if a delivery to this
    /// input can wait at all (a fifo with the `Block` policy); `None` otherwise.
    pub(crate) fn room(&self) -> Option<usize> {
        self.end.room()
    }

    /// Move what is queued at this input to `to`, if it is of the same kind and packet
    /// type (otherwise nothing moves). Returns how many packets (or events) moved.
    pub(crate) fn transfer_to(&self, to: &ErasedInput) -> u64 {
        if self.type_id == to.type_id && self.kind == to.kind {
            self.end.transfer(to)
        } else {
            0
        }
    }

    /// Empty this input's queue, counting the packets as lost at it (overflows, with a
    /// `MonitorEvent::Overflow`): its component is retired and will never read them.
    /// Returns how many there were.
    pub(crate) fn discard_queued(&self) -> u64 {
        let lost = self.end.discard();
        if lost > 0 {
            self.core.overflowed(lost);
        }
        lost
    }

    /// Count `lost` packets as lost at this input, from outside its component: packets
    /// meant for it that never reached it (a network bridge's packet that did not
    /// decode, or that it could not send). They are added to the input's `overflows`
    /// and announced as a `MonitorEvent::Overflow` on its component's monitoring
    /// port, like a packet its own overflow policy dropped. Zero does nothing.
    pub fn count_loss(&self, lost: u64) {
        if lost > 0 {
            self.core.overflowed(lost);
        }
    }

    /// [`ErasedInput::count_loss`] for packets a compound's exported input left this
    /// input out of (a redundant member that stalled), counted apart too.
    pub(crate) fn count_left_behind(&self, lost: u64) {
        if lost > 0 {
            self.core.left_behind.fetch_add(lost, Ordering::AcqRel);
            self.core.overflowed(lost);
        }
    }
}

impl InputEnd for TickInner {
    fn feeder(&self) -> ErasedOutput {
        TickOut::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        let Some(to) = input_as::<TickInner>(to) else {
            return 0;
        };
        let count = self.count.swap(0, Ordering::AcqRel);
        if count > 0 {
            to.count.fetch_add(count, Ordering::AcqRel);
            to.core.arrived();
        }
        count
    }
}

/// Deliver `packets` to `to` (an input of `T`): how many.
pub(super) fn transfer_queue<T: Packet>(packets: Vec<Parcel<T>>, to: &ErasedInput) -> u64 {
    let count = packets.len() as u64;
    if let Some(target) = data_target::<T>(to) {
        for packet in packets {
            target.deliver(packet);
        }
    }
    count
}

impl<T: Packet> InputEnd for FifoInner<T> {
    fn feeder(&self) -> ErasedOutput {
        DataOut::<T>::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        transfer_queue(self.drain().collect(), to)
    }

    fn discard(&self) -> u64 {
        self.drain().count() as u64
    }

    fn room(&self) -> Option<usize> {
        (self.policy == OverflowPolicy::Block).then(|| self.capacity.saturating_sub(self.queued()))
    }
}

impl<T: Packet> InputEnd for UfifoInner<T> {
    fn feeder(&self) -> ErasedOutput {
        DataOut::<T>::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        let packets: Vec<Parcel<T>> = std::mem::take(&mut lock(&self.queue).packets).into();
        transfer_queue(packets, to)
    }

    fn discard(&self) -> u64 {
        std::mem::take(&mut lock(&self.queue).packets).len() as u64
    }
}

impl<T: Packet> InputEnd for LastInner<T> {
    fn feeder(&self) -> ErasedOutput {
        DataOut::<T>::new().erased()
    }

    fn transfer(&self, to: &ErasedInput) -> u64 {
        // Only a packet the old consumer has not taken yet is handed on.
        let unread = self
            .slot
            .read(|reading| reading.is_new().then(|| reading.packet.clone()))
            .flatten();
        match unread {
            Some(packet) => transfer_queue(vec![packet], to),
            None => 0,
        }
    }
}

impl<T: Packet> InputEnd for PosterInInner<T> {
    fn feeder(&self) -> ErasedOutput {
        PosterOut::<T>::new().erased()
    }

    fn clear_source(&self, output: usize) {
        let mut source = write(&self.source);
        if source.as_ref().is_some_and(|(id, _)| *id == output) {
            *source = None;
            // (Under the write lock: no read is between its look and its `seen`.)
            self.seen.store(0, Ordering::Release);
        }
    }
}

impl fmt::Debug for ErasedInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} input of {}", self.kind.name(), self.type_name)
    }
}

/// An output port with its packet type erased (see [`OutputPort`]).
#[derive(Clone)]
pub struct ErasedOutput {
    pub(crate) kind: OutKind,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) core: Arc<OutputCore>,
    pub(super) end: Arc<dyn OutputEnd>,
}

impl fmt::Debug for ErasedOutput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} output of {}", self.kind.name(), self.type_name)
    }
}

impl ErasedOutput {
    /// Connect to `input`, whose kind and packet type were already checked. Returns
    /// false if the input is not of this output's packet type after all.
    pub(crate) fn link(&self, input: &ErasedInput) -> bool {
        self.end.link(self, input)
    }

    /// Disconnect from `input`. Packets already queued at the input stay there.
    pub(crate) fn unlink(&self, input: &ErasedInput) {
        self.end.unlink(self, input)
    }

    /// Move this output's connection from input `old` to input `new` (of the same kind
    /// and type, checked by the caller) in one step, with what is queued at `old`:
    /// while it runs no packet is sent, so none is lost, duplicated or reordered.
    pub(crate) fn relink(&self, old: &ErasedInput, new: &ErasedInput) -> bool {
        self.end.relink(self, old, new)
    }
}

/// A typed input handle that can be registered with [`crate::PortSet`].
pub trait InputPort {
    /// The handle with its packet type erased.
    fn erased(&self) -> ErasedInput;
}

/// A typed output handle that can be registered with [`crate::PortSet`].
pub trait OutputPort {
    /// The handle with its packet type erased.
    fn erased(&self) -> ErasedOutput;
}

/// Packet type of event ports.
pub(super) struct Event;

impl InputPort for TickIn {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Tick,
            type_id: TypeId::of::<Event>(),
            type_name: "event",
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for FifoIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Fifo,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for UfifoIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Ufifo,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for LastIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Last,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(self.inner.core()),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> InputPort for PosterIn<T> {
    fn erased(&self) -> ErasedInput {
        ErasedInput {
            kind: InKind::Poster,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl OutputPort for TickOut {
    fn erased(&self) -> ErasedOutput {
        ErasedOutput {
            kind: OutKind::Tick,
            type_id: TypeId::of::<Event>(),
            type_name: "event",
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> OutputPort for DataOut<T> {
    fn erased(&self) -> ErasedOutput {
        ErasedOutput {
            kind: OutKind::Data,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

impl<T: Packet> OutputPort for PosterOut<T> {
    fn erased(&self) -> ErasedOutput {
        ErasedOutput {
            kind: OutKind::Poster,
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            core: Arc::clone(&self.inner.core),
            end: self.inner.clone(),
        }
    }
}

/// Replace a snapshot list with `f` applied to a copy of it.
pub(super) fn update_list<X: Clone>(list: &RwLock<Arc<[X]>>, f: impl FnOnce(&mut Vec<X>)) {
    let mut guard = write(list);
    let mut items: Vec<X> = guard.iter().cloned().collect();
    f(&mut items);
    *guard = Arc::from(items);
}

impl OutputEnd for TickOutInner {
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
        let input = TickIn::new();
        let erased = input.erased();
        self.link(output, &erased).then(|| {
            let any: Arc<dyn Any + Send + Sync> = Arc::new(input);
            (erased.core.id, any)
        })
    }

    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool {
        let Some(target) = input_as::<TickInner>(input) else {
            return false;
        };
        update_list(&self.targets, |targets| {
            targets.push(TickTarget::Input(target))
        });
        input.core.add_source(Arc::clone(&output.core));
        true
    }

    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput) {
        update_list(&self.targets, |targets| {
            targets.retain(|t| t.id() != input.core.id)
        });
        input.core.remove_source(output.core.id);
    }

    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool {
        let Some(target) = input_as::<TickInner>(new) else {
            return false;
        };
        let mut targets = write(&self.targets);
        let mut items: Vec<_> = targets
            .iter()
            .filter(|t| t.id() != old.core.id)
            .cloned()
            .collect();
        items.push(TickTarget::Input(target));
        *targets = Arc::from(items);
        old.end.transfer(new);
        drop(targets);
        old.core.remove_source(output.core.id);
        new.core.add_source(Arc::clone(&output.core));
        true
    }

    fn remove_sink(&self, id: usize) {
        update_list(&self.targets, |targets| targets.retain(|t| t.id() != id));
    }
}

/// The data-receiving end of `input` as a `Deliver<T>`, if it is a last, fifo or ufifo
/// input of `T`.
pub(super) fn data_target<T: Packet>(input: &ErasedInput) -> Option<Arc<dyn Deliver<T>>> {
    match input.kind {
        InKind::Fifo => input_as::<FifoInner<T>>(input).map(|x| x as Arc<dyn Deliver<T>>),
        InKind::Ufifo => input_as::<UfifoInner<T>>(input).map(|x| x as Arc<dyn Deliver<T>>),
        InKind::Last => input_as::<LastInner<T>>(input).map(|x| x as Arc<dyn Deliver<T>>),
        InKind::Tick | InKind::Poster => None,
    }
}

impl<T: Packet> DataOutInner<T> {
    fn add_sink(&self, output: &ErasedOutput, input: &ErasedInput, target: Arc<dyn Deliver<T>>) {
        self.sinks.update(&self.core, |sinks| {
            sinks.push(Sink {
                input_id: input.core.id,
                target,
            })
        });
        input.core.add_source(Arc::clone(&output.core));
    }

    /// Replace, in one write of the sinks, the sink at input `old` by `target`
    /// (delivering to input `new`, directly or through a converter), and move what
    /// is queued at `old` to `new` (if both take the same packet type).
    fn swap_sink(
        &self,
        output: &ErasedOutput,
        old: &ErasedInput,
        new: &ErasedInput,
        target: Arc<dyn Deliver<T>>,
    ) {
        // Under the change, no delivery to the old snapshot is in flight (`Sinks`):
        // the queued packets move before any newer one arrives at `new`.
        self.sinks.update_then(
            &self.core,
            |sinks| {
                sinks.retain(|sink| sink.input_id != old.core.id);
                sinks.push(Sink {
                    input_id: new.core.id,
                    target,
                });
            },
            || {
                if old.type_id == new.type_id && old.kind == new.kind {
                    old.end.transfer(new);
                }
            },
        );
        old.core.remove_source(output.core.id);
        new.core.add_source(Arc::clone(&output.core));
    }
}

impl<T: Packet> OutputEnd for DataOutInner<T> {
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
        let collected = Arc::new(Collected::<T>::default());
        let id = tap_data::<T>(output, collected.clone())?;
        let any: Arc<dyn Any + Send + Sync> = collected;
        Some((id, any))
    }

    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool {
        match data_target::<T>(input) {
            Some(target) => {
                self.add_sink(output, input, target);
                true
            }
            None => false,
        }
    }

    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput) {
        self.sinks.update(&self.core, |sinks| {
            sinks.retain(|sink| sink.input_id != input.core.id)
        });
        input.core.remove_source(output.core.id);
    }

    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool {
        match data_target::<T>(new) {
            Some(target) => {
                self.swap_sink(output, old, new, target);
                true
            }
            None => false,
        }
    }

    fn forward_from(&self, this: &ErasedOutput, from: &ErasedOutput, id: usize) -> bool {
        let (Some(out), Some(to)) = (
            output_as::<DataOutInner<T>>(from),
            output_as::<DataOutInner<T>>(this),
        ) else {
            return false;
        };
        out.sinks.update(&out.core, |sinks| {
            sinks.push(Sink {
                input_id: id,
                target: Arc::new(DataForward { to }),
            })
        });
        true
    }

    fn remove_sink(&self, id: usize) {
        self.sinks
            .update(&self.core, |sinks| sinks.retain(|sink| sink.input_id != id));
    }

    fn merge(&self, lanes: usize) -> Option<Arc<dyn MergeEnd>> {
        Some(DataOutInner::<T>::new_merge(lanes))
    }
}

pub(super) fn set_poster_source<T: Packet>(
    output: &ErasedOutput,
    input: &ErasedInput,
    source: Arc<dyn PosterSource<T>>,
    out_readers: &RwLock<Arc<[Arc<InputCore>]>>,
) -> bool {
    let Some(reader) = input_as::<PosterInInner<T>>(input) else {
        return false;
    };
    {
        let mut slot = write(&reader.source);
        *slot = Some((output.core.id, source));
        // A new source numbers its posts from 1: nothing of it has been read yet.
        reader.seen.store(0, Ordering::Release);
    }
    update_list(out_readers, |readers| readers.push(Arc::clone(&input.core)));
    input.core.add_source(Arc::clone(&output.core));
    true
}

impl<T: Packet> OutputEnd for PosterOutInner<T> {
    fn collector(&self, output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
        let collected = Arc::new(Collected::<T>::default());
        let id = tap_data::<T>(output, collected.clone())?;
        let any: Arc<dyn Any + Send + Sync> = collected;
        Some((id, any))
    }

    fn link(&self, output: &ErasedOutput, input: &ErasedInput) -> bool {
        let Some(this) = output_as::<PosterOutInner<T>>(output) else {
            return false;
        };
        let source: Arc<dyn PosterSource<T>> = this;
        set_poster_source(output, input, source, &self.readers)
    }

    fn unlink(&self, output: &ErasedOutput, input: &ErasedInput) {
        update_list(&self.readers, |readers| {
            readers.retain(|r| r.id != input.core.id)
        });
        // The input's packet type may differ from T (a converter): clear its source
        // through the input's own end, only if it still reads this output (a replacing
        // connection may have been made first).
        input.end.clear_source(output.core.id);
        input.core.remove_source(output.core.id);
    }

    fn relink(&self, output: &ErasedOutput, old: &ErasedInput, new: &ErasedInput) -> bool {
        // A poster input holds no queue: it reads the producer's post.
        if !self.link(output, new) {
            return false;
        }
        self.unlink(output, old);
        true
    }

    fn forward_from(&self, this: &ErasedOutput, from: &ErasedOutput, id: usize) -> bool {
        let (Some(out), Some(to)) = (
            output_as::<PosterOutInner<T>>(from),
            output_as::<PosterOutInner<T>>(this),
        ) else {
            return false;
        };
        out.add_tap(Sink {
            input_id: id,
            target: Arc::new(PosterForward {
                to: PosterOut { inner: to },
            }),
        });
        true
    }

    fn remove_sink(&self, id: usize) {
        let mut taps = write(&self.taps);
        let kept: Vec<Sink<T>> = taps
            .iter()
            .filter(|tap| tap.input_id != id)
            .cloned()
            .collect();
        self.tapped.store(!kept.is_empty(), Ordering::Release);
        *taps = Arc::from(kept);
    }
}

impl<T: Packet> PosterOutInner<T> {
    /// Deliver every post to `tap` too (a recorder's tap, an exported output).
    pub(super) fn add_tap(&self, tap: Sink<T>) {
        let mut taps = write(&self.taps);
        let mut list: Vec<Sink<T>> = taps.iter().cloned().collect();
        list.push(tap);
        *taps = Arc::from(list);
        self.tapped.store(true, Ordering::Release);
    }
}

/// Connect a data or poster output of `A` to an input of `B` through `convert`.
/// Returns false if the kinds or types do not match `A` and `B`.
pub(crate) fn link_converted<A: Packet, B: Packet>(
    output: &ErasedOutput,
    input: &ErasedInput,
    convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
) -> bool {
    match output.kind {
        OutKind::Data => match (
            output_as::<DataOutInner<A>>(output),
            data_target::<B>(input),
        ) {
            (Some(out), Some(target)) => {
                out.add_sink(output, input, Arc::new(Converted { convert, target }));
                true
            }
            _ => false,
        },
        OutKind::Poster => {
            let Some(out) = output_as::<PosterOutInner<A>>(output) else {
                return false;
            };
            let source: Arc<dyn PosterSource<B>> = Arc::new(ConvertedPoster {
                convert,
                source: Arc::clone(&out),
            });
            set_poster_source(output, input, source, &out.readers)
        }
        OutKind::Tick => false,
    }
}

/// [`link_converted`], replacing `output`'s connection to input `old` (if given) in
/// one step: a data output's sink is swapped under one write of its sinks, with the
/// packets queued at `old` moved to `input` (no packet sent meanwhile is lost); a
/// poster's readers are switched (a poster input holds no queue).
pub(crate) fn relink_converted<A: Packet, B: Packet>(
    output: &ErasedOutput,
    old: Option<&ErasedInput>,
    input: &ErasedInput,
    convert: Arc<dyn Fn(&A) -> B + Send + Sync>,
) -> bool {
    let Some(old) = old else {
        return link_converted(output, input, convert);
    };
    match output.kind {
        OutKind::Data => match (
            output_as::<DataOutInner<A>>(output),
            data_target::<B>(input),
        ) {
            (Some(out), Some(target)) => {
                out.swap_sink(output, old, input, Arc::new(Converted { convert, target }));
                true
            }
            _ => false,
        },
        OutKind::Poster => {
            if !link_converted(output, input, convert) {
                return false;
            }
            output.unlink(old);
            true
        }
        OutKind::Tick => false,
    }
}
