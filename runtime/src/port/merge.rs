//! Merging a redundant group's outputs into one stream.

use super::*;

/// How many packets a member that does not lead its group keeps, ahead of the stream,
/// for the moment it leads.
pub(crate) const MERGE_BACKLOG: usize = 1024;

/// A redundant group's data output as one stream (see `docs/runtime.md`,
/// "Redundancy"): every member's output is a lane, numbered by the packets it sent;
/// the stream carries the leader's packets, each sequence number once; the other
/// lanes keep their packets ahead of the stream (up to [`MERGE_BACKLOG`]) so that,
/// when another member leads, the stream goes on from its backlog with no number
/// missing and none doubled.
pub(crate) trait MergeEnd: Send + Sync {
    /// The merged stream's output (consumers connect to it, not to the members).
    fn output(&self) -> ErasedOutput;
    /// Make member output `from` lane `lane` (kind and type checked): false if it is
    /// not a data output of the stream's packet type.
    fn attach(&self, lane: usize, from: &ErasedOutput) -> bool;
    /// Lane `lane` leads from now on: its packets ahead of the stream go out now.
    /// Returns how many went out, and how many numbers were missing before them
    /// (packets its backlog could not keep), which are counted as lost at every
    /// input the stream feeds (directly, through a converter, or through a
    /// compound's exported output).
    fn lead(&self, lane: usize) -> (u64, u64);
    /// Lane `lane` (a member back from recovery) counts on from the stream's number.
    fn rejoin(&self, lane: usize);
    /// Every lane counts on from the stream's number, and `lane` leads (a restart of
    /// the compound: every member starts again).
    fn reset(&self, lane: usize);
}

pub(super) struct Lane<T> {
    pub(super) sent: u64,
    pub(super) backlog: VecDeque<(u64, Parcel<T>)>,
    pub(super) core: Option<Arc<OutputCore>>,
}

pub(super) struct MergeState<T> {
    pub(super) leader: usize,
    /// The number of the last packet of the stream.
    pub(super) delivered: u64,
    pub(super) lanes: Vec<Lane<T>>,
}

pub(super) struct Merge<T> {
    pub(super) out: DataOut<T>,
    pub(super) state: Mutex<MergeState<T>>,
}

impl<T: Packet> Merge<T> {
    fn arrive(&self, lane: usize, packet: Parcel<T>) {
        let mut state = lock(&self.state);
        let state = &mut *state;
        let leader = state.leader;
        let seq = {
            let lane = &mut state.lanes[lane];
            lane.sent += 1;
            lane.sent
        };
        if seq <= state.delivered {
            return; // Already in the stream (sent by the member that led then).
        }
        if lane == leader {
            state.delivered = seq;
            for other in &mut state.lanes {
                while other.backlog.front().is_some_and(|(s, _)| *s <= seq) {
                    other.backlog.pop_front();
                }
            }
            // Under the lock: the stream keeps its order.
            self.out.send_parcel(packet);
        } else {
            let backlog = &mut state.lanes[lane].backlog;
            backlog.push_back((seq, packet));
            if backlog.len() > MERGE_BACKLOG {
                backlog.pop_front();
            }
        }
    }

    fn route_pulls(&self, state: &MergeState<T>) {
        if let Some(core) = &state.lanes[state.leader].core {
            self.out
                .inner
                .core
                .set_route(PullRoute::Output(Arc::clone(core)));
        }
    }
}

/// One member's output as a lane of a merge.
pub(super) struct LaneSink<T> {
    pub(super) merge: Arc<Merge<T>>,
    pub(super) lane: usize,
}

impl<T: Packet> Deliver<T> for LaneSink<T> {
    fn deliver(&self, packet: Parcel<T>) {
        self.merge.arrive(self.lane, packet);
    }

    fn answers(&self, id: usize) -> bool {
        self.merge
            .out
            .inner
            .sinks
            .read()
            .iter()
            .any(|sink| sink.input_id == id || sink.target.answers(id))
    }

    fn deliver_answer(&self, packet: Parcel<T>, id: usize) {
        // A pull answer is for its requester, not part of the stream.
        dispatch_answer(&self.merge.out.inner.sinks.read(), packet, id);
    }

    fn would_wait(&self) -> bool {
        would_wait(&self.merge.out.inner.sinks.read())
    }
}

impl<T: Packet> MergeEnd for Arc<Merge<T>> {
    fn output(&self) -> ErasedOutput {
        self.out.erased()
    }

    fn attach(&self, lane: usize, from: &ErasedOutput) -> bool {
        let Some(out) = output_as::<DataOutInner<T>>(from) else {
            return false;
        };
        let sink = LaneSink {
            merge: Arc::clone(self),
            lane,
        };
        out.sinks.update(&out.core, |sinks| {
            sinks.push(Sink {
                input_id: next_port_id(),
                target: Arc::new(sink),
            })
        });
        let mut state = lock(&self.state);
        state.lanes[lane].core = Some(Arc::clone(&from.core));
        if lane == state.leader {
            self.route_pulls(&state);
        }
        true
    }

    fn lead(&self, lane: usize) -> (u64, u64) {
        let mut state = lock(&self.state);
        state.leader = lane;
        self.route_pulls(&state);
        let backlog = std::mem::take(&mut state.lanes[lane].backlog);
        let (mut replayed, mut missing) = (0, 0);
        for (seq, packet) in backlog {
            if seq > state.delivered {
                missing += seq - state.delivered - 1;
                state.delivered = seq;
                replayed += 1;
                self.out.send_parcel(packet);
            }
        }
        if missing > 0 {
            // The stream's consumers never get them: lost there, counted and
            // announced, so that sent = received + lost holds at each of them.
            for sink in self.out.inner.sinks.read().iter() {
                sink.target.lost(missing);
            }
        }
        (replayed, missing)
    }

    fn rejoin(&self, lane: usize) {
        let mut state = lock(&self.state);
        let delivered = state.delivered;
        let lane = &mut state.lanes[lane];
        lane.sent = delivered;
        lane.backlog.clear();
    }

    fn reset(&self, lane: usize) {
        let mut state = lock(&self.state);
        let delivered = state.delivered;
        for each in &mut state.lanes {
            each.sent = delivered;
            each.backlog.clear();
        }
        state.leader = lane;
        self.route_pulls(&state);
    }
}

impl ErasedOutput {
    /// A merge of `lanes` outputs of this output's kind and packet type (a redundant
    /// group's data output), or `None` for a tick or poster output.
    pub(crate) fn merge(&self, lanes: usize) -> Option<Arc<dyn MergeEnd>> {
        self.end.merge(lanes)
    }
}

impl<T: Packet> DataOutInner<T> {
    pub(super) fn new_merge(lanes: usize) -> Arc<dyn MergeEnd> {
        let out = DataOut::<T>::new();
        // The merged output answers pull requests (routed to the leader).
        out.inner.core.accept_pulls();
        Arc::new(Arc::new(Merge {
            out,
            state: Mutex::new(MergeState {
                leader: 0,
                delivered: 0,
                lanes: (0..lanes)
                    .map(|_| Lane {
                        sent: 0,
                        backlog: VecDeque::new(),
                        core: None,
                    })
                    .collect(),
            }),
        }))
    }
}
