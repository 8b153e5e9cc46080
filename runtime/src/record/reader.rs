//! Reading a recording: [`Reader`], records in file order.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

use super::writer::LOSS_METADATA;
use super::{
    END_METADATA, EventRecord, FORMAT_VERSION, HEADER_METADATA, Header, LOSSES_TOPIC, PacketRecord,
    PortInfo, ReadError, Record,
};

/// Reads a recording: the [`Header`] at once, then the records as an iterator (packets,
/// losses and events in file order, then the [`Summary`](super::Summary) as [`Record::End`] if the
/// recording ended cleanly).
///
/// It streams the file (one record in memory at a time). A recording whose process
/// died before [`Recording::finish`] holds every chunk flushed until then; the
/// reader yields them, then an error for the cut-off end.
///
/// It reads rosbag2 bags too: a recording of the [`RecordFormat::Ros2`] format, and
/// (through [`Reader::open`], which reads the file's summary) a bag that another
/// program wrote, whose ports are then its topics (each `cdr` channel: its topic as
/// path, its schema's name as type, kind `data`), its start the first message's time,
/// and each message's `seq` its number on its topic (rosbag2 writes every sequence
/// as 0).
///
/// [`Recording::finish`]: super::Recording::finish
/// [`RecordFormat::Ros2`]: super::RecordFormat::Ros2
pub struct Reader {
    pub(super) path: PathBuf,
    pub(super) header: Header,
    pub(super) input: Box<dyn Read + Send>,
    pub(super) mcap: mcap::sans_io::LinearReader,
    pub(super) channels: BTreeMap<u16, Topic>,
    /// Records read so far (for error messages).
    pub(super) record: usize,
    /// The data section ended (or an error was yielded).
    pub(super) done: bool,
}

/// What a channel of a recording carries.
#[derive(Debug)]
pub(super) enum Topic {
    /// A tapped output, and the last sequence number read on it (to unwrap the
    /// 32-bit MCAP sequence).
    Port {
        path: String,
        wrapped: bool,
        last: Option<u64>,
        /// Its messages are CDR.
        cdr: bool,
        /// Its sequence numbers are counted, not read (a bag another program wrote).
        counted: bool,
    },
    /// A monitored component's events.
    Events { component: String, wrapped: bool },
    /// The losses.
    Losses { wrapped: bool },
    /// A channel this runtime does not write (ignored).
    Other,
}

/// An MCAP record, owned, as far as a [`Reader`] cares.
pub(super) enum Raw {
    /// The MCAP header: its profile.
    Header(String),
    Metadata(mcap::records::Metadata),
    Channel(mcap::records::Channel),
    Message(mcap::records::MessageHeader, Vec<u8>),
    DataEnd,
    Other,
}

impl std::fmt::Debug for Reader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Reader({})", self.path.display())
    }
}

impl Reader {
    /// Open the recording at `path` and read its header: an MCAP file, or a rosbag2
    /// bag directory holding one (`metadata.yaml` is not read: the MCAP file holds
    /// what it says).
    pub fn open(path: impl AsRef<Path>) -> Result<Reader, ReadError> {
        let mut path = path.as_ref().to_path_buf();
        if path.is_dir() {
            path = bag_file(&path)?;
        }
        let io = |source| ReadError::Io {
            path: path.clone(),
            source,
        };
        let mut file = File::open(&path).map_err(io)?;
        // A bag another program wrote has no header: its ports are read from the
        // summary at the end of the file.
        let summary = read_summary(&mut file).map_err(|source| ReadError::Mcap {
            path: path.clone(),
            source,
        })?;
        file.seek(SeekFrom::Start(0)).map_err(io)?;
        Reader::read(path, Box::new(BufReader::new(file)), summary)
    }

    /// Read a recording from `input` (`path` names it in errors). A rosbag2 bag that
    /// another program wrote is read only by [`Reader::open`].
    pub fn new(path: PathBuf, input: Box<dyn Read + Send>) -> Result<Reader, ReadError> {
        Reader::read(path, input, None)
    }

    fn read(
        path: PathBuf,
        input: Box<dyn Read + Send>,
        summary: Option<mcap::Summary>,
    ) -> Result<Reader, ReadError> {
        let mut reader = Reader {
            path,
            header: Header {
                version: FORMAT_VERSION,
                start_unix_ns: 0,
                capacity: 0,
                ports: Vec::new(),
                monitors: Vec::new(),
            },
            input,
            mcap: mcap::sans_io::LinearReader::new(),
            channels: BTreeMap::new(),
            record: 0,
            done: false,
        };
        // The header metadata comes before any channel.
        let mut profile = String::new();
        loop {
            let raw = match reader.next_raw() {
                Some(Ok(raw)) => raw,
                Some(Err(error)) => return Err(error),
                None => return Err(reader.no_header()),
            };
            match raw {
                Raw::Metadata(metadata) if metadata.name == HEADER_METADATA => {
                    let text = metadata.metadata.get("header").cloned().unwrap_or_default();
                    let value: serde_json::Value = serde_json::from_str(&text)
                        .map_err(|source| reader.json("header", source))?;
                    let version = value.get("version").and_then(serde_json::Value::as_u64);
                    if let Some(found) = version.filter(|v| *v != u64::from(FORMAT_VERSION)) {
                        return Err(ReadError::Version {
                            path: reader.path,
                            found: u32::try_from(found).unwrap_or(u32::MAX),
                        });
                    }
                    reader.header = serde_json::from_value(value)
                        .map_err(|source| reader.json("header", source))?;
                    return Ok(reader);
                }
                Raw::Channel(channel) if profile == "ros2" && summary.is_some() => {
                    reader.header = foreign_header(summary.as_ref());
                    reader.declare(channel);
                    return Ok(reader);
                }
                Raw::Channel(_) | Raw::Message(..) | Raw::DataEnd => {
                    return Err(reader.no_header());
                }
                Raw::Header(found) => profile = found,
                Raw::Metadata(_) | Raw::Other => {}
            }
        }
    }

    pub(super) fn no_header(&self) -> ReadError {
        ReadError::NoHeader {
            path: self.path.clone(),
        }
    }

    pub(super) fn json(&self, what: &'static str, source: serde_json::Error) -> ReadError {
        ReadError::Json {
            path: self.path.clone(),
            record: self.record,
            what,
            source,
        }
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The packets of `port` decoded as `T`, in file order, skipping other records.
    pub fn packets<T: DeserializeOwned>(
        self,
        port: &str,
    ) -> impl Iterator<Item = Result<(PacketRecord, T), ReadError>> {
        let port = port.to_owned();
        self.filter_map(move |record| match record {
            Ok(Record::Packet(packet)) if packet.port == port => {
                Some(packet.decode::<T>().map(|value| (packet, value)))
            }
            Ok(_) => None,
            Err(error) => Some(Err(error)),
        })
    }

    /// The next MCAP record of the data section, chunks unpacked.
    pub(super) fn next_raw(&mut self) -> Option<Result<Raw, ReadError>> {
        loop {
            let event = match self.mcap.next_event()? {
                Ok(event) => event,
                Err(source) => {
                    return Some(Err(ReadError::Mcap {
                        path: self.path.clone(),
                        source,
                    }));
                }
            };
            match event {
                mcap::sans_io::LinearReadEvent::ReadRequest(wanted) => {
                    let buffer = self.mcap.insert(wanted);
                    let read = match self.input.read(buffer) {
                        Ok(read) => read,
                        Err(error) if error.kind() == std::io::ErrorKind::Interrupted => 0,
                        Err(source) => {
                            return Some(Err(ReadError::Io {
                                path: self.path.clone(),
                                source,
                            }));
                        }
                    };
                    self.mcap.notify_read(read);
                }
                mcap::sans_io::LinearReadEvent::Record { data, opcode } => {
                    self.record += 1;
                    let raw = match mcap::parse_record(opcode, data) {
                        Ok(mcap::records::Record::Header(header)) => Raw::Header(header.profile),
                        Ok(mcap::records::Record::Metadata(metadata)) => Raw::Metadata(metadata),
                        Ok(mcap::records::Record::Channel(channel)) => Raw::Channel(channel),
                        Ok(mcap::records::Record::Message { header, data }) => {
                            Raw::Message(header, data.into_owned())
                        }
                        Ok(mcap::records::Record::DataEnd(_)) => Raw::DataEnd,
                        Ok(_) => Raw::Other,
                        Err(source) => {
                            return Some(Err(ReadError::Mcap {
                                path: self.path.clone(),
                                source,
                            }));
                        }
                    };
                    return Some(Ok(raw));
                }
            }
        }
    }

    /// Learn what a channel carries.
    pub(super) fn declare(&mut self, channel: mcap::records::Channel) {
        let wrapped = channel
            .metadata
            .get("coolbot.wrapped")
            .is_some_and(|w| w == "value");
        let topic = if channel.topic == LOSSES_TOPIC {
            Topic::Losses { wrapped }
        } else if let Some(component) = channel.metadata.get("coolbot.monitor") {
            Topic::Events {
                component: component.clone(),
                wrapped,
            }
        } else if channel.message_encoding == "cdr" {
            // A rosbag2 recording's port, or a topic of a bag another program wrote.
            let port = channel.metadata.get("coolbot.port").cloned();
            Topic::Port {
                counted: port.is_none(),
                path: port.unwrap_or(channel.topic),
                wrapped: false,
                last: None,
                cdr: true,
            }
        } else if channel.metadata.contains_key("coolbot.kind") {
            Topic::Port {
                path: channel.topic,
                wrapped,
                last: None,
                cdr: false,
                counted: false,
            }
        } else {
            Topic::Other
        };
        self.channels.insert(channel.id, topic);
    }

    /// A message as a record; `None` for a channel this runtime does not write.
    pub(super) fn message(
        &mut self,
        header: mcap::records::MessageHeader,
        data: &[u8],
    ) -> Result<Option<Record>, ReadError> {
        let t = header.log_time.saturating_sub(self.header.start_unix_ns);
        let record = self.record;
        let Some(topic) = self.channels.get_mut(&header.channel_id) else {
            return Err(ReadError::UnknownChannel {
                path: self.path.clone(),
                record,
                channel: header.channel_id,
            });
        };
        let parse = |wrapped: bool| -> Result<serde_json::Value, serde_json::Error> {
            let value: serde_json::Value = serde_json::from_slice(data)?;
            Ok(if wrapped {
                value
                    .get("value")
                    .cloned()
                    .unwrap_or(serde_json::Value::Null)
            } else {
                value
            })
        };
        match topic {
            Topic::Port {
                path,
                wrapped,
                last,
                cdr,
                counted,
            } => {
                // The MCAP sequence is the packet's number modulo 2^32: the number is
                // the one nearest the last one read (packets sent from several threads
                // at once may be written slightly out of order, so a smaller number is
                // not always a wrap).
                let low = u64::from(header.sequence);
                let seq = match *last {
                    _ if *counted => last.map_or(0, |previous| previous + 1),
                    None => low,
                    Some(previous) => {
                        let candidate = (previous & !0xffff_ffff) | low;
                        [
                            candidate.checked_sub(1 << 32),
                            Some(candidate),
                            candidate.checked_add(1 << 32),
                        ]
                        .into_iter()
                        .flatten()
                        .min_by_key(|seq| seq.abs_diff(previous))
                        .unwrap_or(candidate)
                    }
                };
                *last = Some(seq);
                let port = path.clone();
                if *cdr {
                    return Ok(Some(Record::Packet(PacketRecord {
                        t,
                        port,
                        seq,
                        value: serde_json::Value::Null,
                        cdr: Some(data.to_vec()),
                    })));
                }
                let value = parse(*wrapped).map_err(|source| self.json("a packet", source))?;
                Ok(Some(Record::Packet(PacketRecord {
                    t,
                    port,
                    seq,
                    value,
                    cdr: None,
                })))
            }
            Topic::Events { component, wrapped } => {
                let component = component.clone();
                let value = parse(*wrapped).map_err(|source| self.json("an event", source))?;
                let event = serde_json::from_value(value)
                    .map_err(|source| self.json("a monitoring event", source))?;
                Ok(Some(Record::Event(EventRecord {
                    t,
                    component,
                    event,
                })))
            }
            Topic::Losses { wrapped } => {
                let value = parse(*wrapped).map_err(|source| self.json("a loss", source))?;
                let loss =
                    serde_json::from_value(value).map_err(|source| self.json("a loss", source))?;
                Ok(Some(Record::Lost(loss)))
            }
            Topic::Other => Ok(None),
        }
    }
}

impl Iterator for Reader {
    type Item = Result<Record, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let raw = match self.next_raw() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(error)) => {
                    self.done = true;
                    return Some(Err(error));
                }
                Some(Ok(raw)) => raw,
            };
            match raw {
                Raw::Channel(channel) => self.declare(channel),
                Raw::Message(header, data) => match self.message(header, &data) {
                    Ok(Some(record)) => return Some(Ok(record)),
                    Ok(None) => {}
                    Err(error) => return Some(Err(error)),
                },
                Raw::Metadata(metadata) if metadata.name == LOSS_METADATA => {
                    let text = metadata.metadata.get("loss").cloned().unwrap_or_default();
                    return Some(
                        serde_json::from_str(&text)
                            .map(Record::Lost)
                            .map_err(|source| self.json("a loss", source)),
                    );
                }
                Raw::Metadata(metadata) if metadata.name == END_METADATA => {
                    let text = metadata
                        .metadata
                        .get("summary")
                        .cloned()
                        .unwrap_or_default();
                    return Some(
                        serde_json::from_str(&text)
                            .map(Record::End)
                            .map_err(|source| self.json("the summary", source)),
                    );
                }
                // The summary section repeats the channels: nothing more to read.
                Raw::DataEnd => self.done = true,
                Raw::Header(_) | Raw::Metadata(_) | Raw::Other => {}
            }
        }
        None
    }
}

/// The one MCAP file of the rosbag2 bag directory `dir`.
fn bag_file(dir: &Path) -> Result<PathBuf, ReadError> {
    let io = |source| ReadError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path.extension().is_some_and(|ext| ext == "mcap") {
            files.push(path);
        }
    }
    match <[PathBuf; 1]>::try_from(files) {
        Ok([file]) => Ok(file),
        Err(files) => Err(ReadError::BagFiles {
            path: dir.to_path_buf(),
            found: files.len(),
        }),
    }
}

/// The summary section of an MCAP file (`None` if it has none).
fn read_summary(file: &mut File) -> mcap::McapResult<Option<mcap::Summary>> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader};
    let mut reader = SummaryReader::new();
    while let Some(event) = reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(need) => {
                let read = file.read(reader.insert(need))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                reader.notify_seeked(file.seek(to)?);
            }
        }
    }
    Ok(reader.finish())
}

/// The header of a rosbag2 bag that another program wrote: its `cdr` channels as
/// ports, in channel order, and its first message's time as its start.
fn foreign_header(summary: Option<&mcap::Summary>) -> Header {
    let mut ports = Vec::new();
    let mut start_unix_ns = 0;
    if let Some(summary) = summary {
        let mut channels: Vec<_> = summary.channels.values().collect();
        channels.sort_by_key(|channel| channel.id);
        for channel in channels {
            if channel.message_encoding != "cdr" {
                continue;
            }
            ports.push(PortInfo {
                path: channel.topic.clone(),
                type_name: channel
                    .schema
                    .as_ref()
                    .map(|schema| schema.name.clone())
                    .unwrap_or_default(),
                kind: "data".to_owned(),
            });
        }
        start_unix_ns = summary
            .stats
            .as_ref()
            .map_or(0, |stats| stats.message_start_time);
    }
    Header {
        version: FORMAT_VERSION,
        start_unix_ns,
        capacity: 0,
        ports,
        monitors: Vec::new(),
    }
}
