//! A thread that serves what a channel brings, one request at a time, and sleeps
//! in between: a node's control thread and its replier. Dropping the [`Server`]
//! stops the thread and joins it.

use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender};

use crate::Error;

/// What a stopping server does with the requests still queued.
#[derive(Clone, Copy)]
pub(crate) enum AtStop {
    /// Serve them first.
    Serve,
    /// Drop them (after the one being served).
    Drop,
}

/// A serving thread; stopped and joined when dropped.
pub(crate) struct Server {
    /// Dropped to stop the thread (which sleeps until a request or this).
    stop: Option<Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Server {
    /// Start the thread `name` (`what` names it in a spawn error), calling `serve`
    /// with each request of `requests` until the server is dropped or every sender
    /// of `requests` is.
    pub(crate) fn start<T: Send + 'static>(
        name: String,
        what: &'static str,
        requests: Receiver<T>,
        at_stop: AtStop,
        mut serve: impl FnMut(T) + Send + 'static,
    ) -> Result<Server, Error> {
        let (stop, stopped) = crossbeam_channel::bounded::<()>(0);
        let thread = std::thread::Builder::new()
            .name(name)
            .spawn(move || {
                loop {
                    crossbeam_channel::select_biased! {
                        recv(stopped) -> _ => {
                            if let AtStop::Serve = at_stop {
                                requests.try_iter().for_each(&mut serve);
                            }
                            break;
                        }
                        recv(requests) -> request => match request {
                            Ok(request) => serve(request),
                            Err(_) => break,
                        },
                    }
                }
            })
            .map_err(Error::spawn(what))?;
        Ok(Server {
            stop: Some(stop),
            thread: Some(thread),
        })
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
