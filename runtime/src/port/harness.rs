//! What a harness (`crate::harness`) needs of the ports: collectors of what an
//! output sends, feeders of an input, canned pull answers.

use super::*;

/// The packets an output sent to a harness's collector, in order.
pub(crate) struct Collected<T> {
    pub(super) packets: Mutex<Vec<T>>,
}

impl<T> Default for Collected<T> {
    fn default() -> Self {
        Collected {
            packets: Mutex::new(Vec::new()),
        }
    }
}

impl<T: Packet> Collected<T> {
    /// The packets collected since the last call.
    pub(crate) fn take(&self) -> Vec<T> {
        std::mem::take(&mut *lock(&self.packets))
    }
}

impl<T: Packet> Deliver<T> for Collected<T> {
    fn deliver(&self, packet: Parcel<T>) {
        lock(&self.packets).push(packet.into_owned());
    }
}

/// The input end of `input` that feeds it (see `InputEnd::feeder`), not connected.
pub(crate) fn feeder_of(input: &ErasedInput) -> ErasedOutput {
    input.end.feeder()
}

/// The collector of `output` (see `OutputEnd::collector`).
pub(crate) fn collector_of(output: &ErasedOutput) -> Option<(usize, Arc<dyn Any + Send + Sync>)> {
    output.end.collector(output)
}

/// The typed data output behind `output`, if it is a `DataOut<T>`.
pub(crate) fn data_out<T: Packet>(output: &ErasedOutput) -> Option<DataOut<T>> {
    output_as::<DataOutInner<T>>(output).map(|inner| DataOut { inner })
}

/// The typed poster output behind `output`, if it is a `PosterOut<T>`.
pub(crate) fn poster_out<T: Packet>(output: &ErasedOutput) -> Option<PosterOut<T>> {
    output_as::<PosterOutInner<T>>(output).map(|inner| PosterOut { inner })
}

/// The tick output behind `output`, if it is one.
pub(crate) fn tick_out(output: &ErasedOutput) -> Option<TickOut> {
    output_as::<TickOutInner>(output).map(|inner| TickOut { inner })
}

/// Pull requests to `output` are answered by `answer`, called at once on the
/// requester's thread (a harness's canned answers).
pub(crate) fn answer_pulls_with(output: &ErasedOutput, answer: Arc<dyn Fn() + Send + Sync>) {
    output.core.set_route(PullRoute::Answer(answer));
}

/// A pull request to `output` on behalf of the input (or tap) with id `input_id`.
pub(crate) fn request_on_behalf(output: &ErasedOutput, input_id: usize) -> Result<(), PullError> {
    output.core.request(input_id)
}
