//! One MCAP file of a bag, read two ways: a first pass over every record (what the index
//! of a bag is built from) and random access to one message later.
//!
//! An MCAP file is the magic `\x89MCAP0\r\n`, then records (`opcode: u8`, `length: u64` LE,
//! body), then the magic again. Messages sit in Chunk records (compressed with zstd or lz4,
//! or not), or on their own. Schema and Channel records come before the messages that use
//! them. DataEnd ends the data section; the summary after it repeats the schemas and
//! channels and indexes the chunks (which topics each holds).
//!
//! Steps of [`scan`]: (1) the summary, when the file has an intact one, says which chunks
//! hold none of the wanted channels: those are skipped; (2) the records from the start are
//! read in order, each length checked against the file before it is read; (3) a chunk is
//! decompressed (its size and CRC checked) and its records walked; (4) each message is
//! handed to the caller with its [`MessageLocation`] (the chunk's file offset and the
//! record's offset inside it) so it can be read again with [`McapFile::message`]. A file
//! that ends before DataEnd or the footer is truncated, and said so.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::{op, ChunkHeader, MessageHeader, Record};
use mcap::sans_io::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};

use crate::DatasetError;

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Opcode (1) and length (8) before every record body.
const RECORD_PREFIX: u64 = 9;

/// A channel of the file: its topic and message type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ChannelInfo {
    pub topic: String,
    /// The schema's name, e.g. `sensor_msgs/msg/Image`; empty when the channel has none.
    pub type_name: String,
    pub message_encoding: String,
}

/// Where a message lies in its file, to read it again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum MessageLocation {
    /// In the chunk record at `chunk` (file offset), at `offset` of its decompressed records.
    Chunked { chunk: u64, offset: u64 },
    /// A message record on its own at this file offset.
    Plain { record: u64 },
}

/// One message met by [`scan`].
pub(crate) struct ScannedMessage<'a> {
    pub channel: &'a Arc<ChannelInfo>,
    pub location: MessageLocation,
    pub data: &'a [u8],
}

/// An MCAP file opened for reading.
pub(crate) struct McapFile {
    path: PathBuf,
    file: File,
    size: u64,
    /// The most recently decompressed chunks (file offset, records), newest last.
    cache: Vec<(u64, Vec<u8>)>,
}

/// Decompressed chunks kept for random access: a frame's colour and depth images usually
/// lie in the same chunk or in neighbours.
const CACHED_CHUNKS: usize = 3;

fn invalid(path: &Path, message: impl Into<String>) -> DatasetError {
    DatasetError::invalid(path, message)
}

fn opcode_name(opcode: u8) -> String {
    match opcode {
        op::HEADER => "header".into(),
        op::SCHEMA => "schema".into(),
        op::CHANNEL => "channel".into(),
        op::MESSAGE => "message".into(),
        op::CHUNK => "chunk".into(),
        op::MESSAGE_INDEX => "message index".into(),
        op::ATTACHMENT => "attachment".into(),
        op::METADATA => "metadata".into(),
        other => format!("opcode {other:#04x}"),
    }
}

impl McapFile {
    /// Opens a file and checks that it starts with the MCAP magic.
    pub fn open(path: &Path) -> Result<Self, DatasetError> {
        let mut file = File::open(path).map_err(|e| DatasetError::io(path, e))?;
        let size = file
            .metadata()
            .map_err(|e| DatasetError::io(path, e))?
            .len();
        let mut magic = [0u8; 8];
        if size < 8 || file.read_exact(&mut magic).is_err() || &magic != MAGIC {
            let hint = if magic.starts_with(b"SQLite format 3") {
                ": it is an SQLite (.db3) bag; only MCAP is read (convert it, see --help)"
            } else {
                ""
            };
            return Err(invalid(
                path,
                format!("not an MCAP file (no MCAP magic at its start){hint}"),
            ));
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            size,
            cache: Vec::new(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// From an intact summary (`None` without one): its channels, and the chunks (file
    /// offsets) whose index lists channels, none of them `wanted`.
    fn summary(
        &mut self,
        wanted: &dyn Fn(&ChannelInfo) -> bool,
    ) -> Option<(Channels, HashSet<u64>)> {
        let mut reader = SummaryReader::new_with_options(
            SummaryReaderOptions::default()
                .with_file_size(self.size)
                .with_record_length_limit(usize::try_from(self.size).unwrap_or(usize::MAX)),
        );
        while let Some(event) = reader.next_event() {
            match event.ok()? {
                SummaryReadEvent::ReadRequest(n) => {
                    let read = self.file.read(reader.insert(n)).ok()?;
                    reader.notify_read(read);
                }
                SummaryReadEvent::SeekRequest(to) => {
                    reader.notify_seeked(self.file.seek(to).ok()?);
                }
            }
        }
        let summary = reader.finish()?;
        let mut channels = Channels::default();
        for (id, s) in &summary.schemas {
            channels.schemas.insert(*id, s.name.clone());
        }
        for (id, c) in &summary.channels {
            let info = ChannelInfo {
                topic: c.topic.clone(),
                type_name: c
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                message_encoding: c.message_encoding.clone(),
            };
            channels.channels.insert(*id, Arc::new(info));
        }
        let skip = summary
            .chunk_indexes
            .iter()
            .filter(|c| {
                !c.message_index_offsets.is_empty()
                    && !c.message_index_offsets.keys().any(|id| {
                        channels
                            .channels
                            .get(id)
                            .is_none_or(|channel| wanted(channel))
                    })
            })
            .map(|c| c.chunk_start_offset)
            .collect();
        Some((channels, skip))
    }

    /// Reads every record from the start, handing each message of a `wanted` channel to
    /// `visit` in file order (chunks the summary shows to hold none are skipped). `visit`'s
    /// errors stop the scan.
    pub fn scan(
        &mut self,
        wanted: &dyn Fn(&ChannelInfo) -> bool,
        visit: &mut dyn FnMut(ScannedMessage) -> Result<(), DatasetError>,
    ) -> Result<(), DatasetError> {
        let (mut channels, skip) = self.summary(wanted).unwrap_or_default();
        let path = self.path.clone();
        let size = self.size;
        self.file
            .seek(SeekFrom::Start(8))
            .map_err(|e| DatasetError::io(&path, e))?;
        let mut reader = BufReader::with_capacity(1 << 16, &mut self.file);
        let mut pos = 8u64;
        let mut body = Vec::new();
        loop {
            if pos == size {
                return Err(invalid(
                    &path,
                    format!(
                        "truncated: the file ends at byte {size} without the end of its data \
                         section (a recording that did not finish? `mcap recover` repairs it)"
                    ),
                ));
            }
            let mut prefix = [0u8; RECORD_PREFIX as usize];
            if size - pos < RECORD_PREFIX || reader.read_exact(&mut prefix).is_err() {
                return Err(invalid(
                    &path,
                    format!("truncated: the file ends inside the record at byte {pos}"),
                ));
            }
            let opcode = prefix[0];
            let mut len_bytes = [0u8; 8];
            len_bytes.copy_from_slice(&prefix[1..]);
            let len = u64::from_le_bytes(len_bytes);
            let body_start = pos + RECORD_PREFIX;
            if len > size - body_start {
                return Err(invalid(
                    &path,
                    format!(
                        "truncated: the {} record at byte {pos} is {len} bytes long, but the \
                         file ends {} bytes after its start",
                        opcode_name(opcode),
                        size - body_start
                    ),
                ));
            }
            let record_at = pos;
            pos = body_start + len;
            match opcode {
                op::DATA_END | op::FOOTER => return Ok(()),
                op::CHUNK if skip.contains(&record_at) => {
                    skip_bytes(&mut reader, len).map_err(|e| DatasetError::io(&path, e))?;
                }
                op::SCHEMA | op::CHANNEL | op::MESSAGE | op::CHUNK => {
                    body.clear();
                    (&mut reader)
                        .take(len)
                        .read_to_end(&mut body)
                        .map_err(|e| DatasetError::io(&path, e))?;
                    if body.len() as u64 != len {
                        return Err(invalid(
                            &path,
                            format!("truncated: the record at byte {record_at} is cut short"),
                        ));
                    }
                    let at = |m: String| {
                        invalid(
                            &path,
                            format!("{} record at byte {record_at}: {m}", opcode_name(opcode)),
                        )
                    };
                    match mcap::parse_record(opcode, &body).map_err(|e| at(e.to_string()))? {
                        Record::Chunk { header, data } => {
                            let records = decompress(&header, &data).map_err(at)?;
                            walk_chunk(&records, |inner_op, offset, inner| {
                                let location = MessageLocation::Chunked {
                                    chunk: record_at,
                                    offset,
                                };
                                channels.record(inner_op, inner, location, wanted, visit)
                            })
                            .map_err(|e| match e {
                                ChunkError::Layout(m) => at(m),
                                ChunkError::Visit(e) => e,
                            })?;
                        }
                        _ => channels
                            .record(
                                opcode,
                                &body,
                                MessageLocation::Plain { record: record_at },
                                wanted,
                                visit,
                            )
                            .map_err(|e| match e {
                                ChunkError::Layout(m) => at(m),
                                ChunkError::Visit(e) => e,
                            })?,
                    }
                }
                _ => skip_bytes(&mut reader, len).map_err(|e| DatasetError::io(&path, e))?,
            }
        }
    }

    /// Reads `len` bytes at `offset` of the file.
    fn read_at(&mut self, offset: u64, len: u64) -> Result<Vec<u8>, DatasetError> {
        let path = &self.path;
        if offset > self.size || len > self.size - offset {
            return Err(invalid(
                path,
                format!("byte range {offset}+{len} lies past the end of the file (it changed?)"),
            ));
        }
        self.file
            .seek(SeekFrom::Start(offset))
            .map_err(|e| DatasetError::io(path, e))?;
        let mut buf = Vec::new();
        (&mut self.file)
            .take(len)
            .read_to_end(&mut buf)
            .map_err(|e| DatasetError::io(path, e))?;
        if buf.len() as u64 != len {
            return Err(invalid(
                path,
                format!("byte range {offset}+{len} is cut short"),
            ));
        }
        Ok(buf)
    }

    /// The record prefix at `offset`: opcode and body length.
    fn record_prefix(&mut self, offset: u64) -> Result<(u8, u64), DatasetError> {
        let p = self.read_at(offset, RECORD_PREFIX)?;
        let mut len = [0u8; 8];
        len.copy_from_slice(&p[1..]);
        Ok((p[0], u64::from_le_bytes(len)))
    }

    /// The decompressed records of the chunk at file offset `chunk`, cached.
    fn chunk_records(&mut self, chunk: u64) -> Result<&[u8], String> {
        if let Some(i) = self.cache.iter().position(|(at, _)| *at == chunk) {
            let entry = self.cache.remove(i);
            self.cache.push(entry);
        } else {
            let (opcode, len) = self.record_prefix(chunk).map_err(|e| e.to_string())?;
            if opcode != op::CHUNK {
                return Err(format!(
                    "no chunk record at byte {chunk} (the file changed?)"
                ));
            }
            let body = self
                .read_at(chunk + RECORD_PREFIX, len)
                .map_err(|e| e.to_string())?;
            let records = match mcap::parse_record(op::CHUNK, &body) {
                Ok(Record::Chunk { header, data }) => decompress(&header, &data)?,
                Ok(_) => return Err(format!("no chunk record at byte {chunk}")),
                Err(e) => return Err(format!("chunk record at byte {chunk}: {e}")),
            };
            if self.cache.len() == CACHED_CHUNKS {
                self.cache.remove(0);
            }
            self.cache.push((chunk, records));
        }
        Ok(self
            .cache
            .last()
            .map(|(_, r)| r.as_slice())
            .unwrap_or_default())
    }

    /// The serialized data of the message at `location` (as [`scan`] found it).
    pub fn message(&mut self, location: MessageLocation) -> Result<Vec<u8>, String> {
        match location {
            MessageLocation::Chunked { chunk, offset } => {
                let records = self.chunk_records(chunk)?;
                let body = record_at(records, offset).ok_or_else(|| {
                    format!("no message at offset {offset} of the chunk at byte {chunk}")
                })?;
                message_data(body).map(|d| d.to_vec())
            }
            MessageLocation::Plain { record } => {
                let (opcode, len) = self.record_prefix(record).map_err(|e| e.to_string())?;
                if opcode != op::MESSAGE {
                    return Err(format!("no message record at byte {record}"));
                }
                let body = self
                    .read_at(record + RECORD_PREFIX, len)
                    .map_err(|e| e.to_string())?;
                message_data(&body).map(|d| d.to_vec())
            }
        }
    }
}

fn skip_bytes(reader: &mut impl Read, len: u64) -> std::io::Result<()> {
    let skipped = std::io::copy(&mut reader.take(len), &mut std::io::sink())?;
    if skipped != len {
        return Err(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "the file ends inside a record",
        ));
    }
    Ok(())
}

/// The payload of a message record's body.
fn message_data(body: &[u8]) -> Result<&[u8], String> {
    const HEADER: usize = 2 + 4 + 8 + 8;
    if body.len() < HEADER {
        return Err(format!(
            "message record of {} bytes has no header",
            body.len()
        ));
    }
    Ok(&body[HEADER..])
}

/// The body of the record at `offset` of a chunk's records, if one fits there.
fn record_at(records: &[u8], offset: u64) -> Option<&[u8]> {
    let start = usize::try_from(offset).ok()?;
    let prefix = records.get(start..start.checked_add(RECORD_PREFIX as usize)?)?;
    if prefix[0] != op::MESSAGE {
        return None;
    }
    let mut len = [0u8; 8];
    len.copy_from_slice(&prefix[1..]);
    let len = usize::try_from(u64::from_le_bytes(len)).ok()?;
    let body_start = start + RECORD_PREFIX as usize;
    records.get(body_start..body_start.checked_add(len)?)
}

/// The uncompressed records of a chunk, their size and CRC checked.
fn decompress(header: &ChunkHeader, data: &[u8]) -> Result<Vec<u8>, String> {
    let size = header.uncompressed_size;
    let mut out = Vec::new();
    // Never trust the declared size for an allocation: read at most one byte more than it.
    let limited = |r: &mut dyn Read, out: &mut Vec<u8>| -> Result<(), String> {
        r.take(size.saturating_add(1))
            .read_to_end(out)
            .map(|_| ())
            .map_err(|e| format!("{} chunk does not decompress: {e}", header.compression))
    };
    match header.compression.as_str() {
        "" => out.extend_from_slice(data),
        "zstd" => {
            let mut d = zstd::stream::read::Decoder::with_buffer(data)
                .map_err(|e| format!("zstd chunk: {e}"))?;
            limited(&mut d, &mut out)?;
        }
        "lz4" => {
            let mut d = lz4::Decoder::new(data).map_err(|e| format!("lz4 chunk: {e}"))?;
            limited(&mut d, &mut out)?;
        }
        other => {
            return Err(format!(
                "chunk compression '{}' is not supported (zstd, lz4 or none)",
                other.escape_debug()
            ))
        }
    }
    if out.len() as u64 != size {
        return Err(format!(
            "chunk holds {} bytes uncompressed, its header says {size}",
            out.len()
        ));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&out);
        if crc != header.uncompressed_crc {
            return Err(format!(
                "chunk CRC {crc:#010x} does not match its header's {:#010x}",
                header.uncompressed_crc
            ));
        }
    }
    Ok(out)
}

enum ChunkError {
    /// The records do not parse; the message says where.
    Layout(String),
    /// The visitor's own error.
    Visit(DatasetError),
}

/// Calls `each(opcode, offset, body)` for every record of a chunk's uncompressed records.
fn walk_chunk(
    records: &[u8],
    mut each: impl FnMut(u8, u64, &[u8]) -> Result<(), ChunkError>,
) -> Result<(), ChunkError> {
    let mut at = 0usize;
    while at < records.len() {
        let Some(prefix) = records.get(at..at + RECORD_PREFIX as usize) else {
            return Err(ChunkError::Layout(format!(
                "the chunk's records end inside a record prefix at offset {at}"
            )));
        };
        let mut len = [0u8; 8];
        len.copy_from_slice(&prefix[1..]);
        let len = u64::from_le_bytes(len);
        let body_start = at + RECORD_PREFIX as usize;
        let body = usize::try_from(len)
            .ok()
            .and_then(|l| records.get(body_start..body_start.checked_add(l)?))
            .ok_or_else(|| {
                ChunkError::Layout(format!(
                    "the record at offset {at} of the chunk is {len} bytes long, past the \
                     chunk's end"
                ))
            })?;
        each(prefix[0], at as u64, body)?;
        at = body_start + body.len();
    }
    Ok(())
}

/// The schemas and channels met so far in a file.
#[derive(Default)]
struct Channels {
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
}

impl Channels {
    /// Registers a schema or channel, or hands a message of a wanted channel to `visit`.
    fn record(
        &mut self,
        opcode: u8,
        body: &[u8],
        location: MessageLocation,
        wanted: &dyn Fn(&ChannelInfo) -> bool,
        visit: &mut dyn FnMut(ScannedMessage) -> Result<(), DatasetError>,
    ) -> Result<(), ChunkError> {
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Ok(());
        }
        let parsed = mcap::parse_record(opcode, body)
            .map_err(|e| ChunkError::Layout(format!("{} record: {e}", opcode_name(opcode))))?;
        match parsed {
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                let type_name = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                self.channels.insert(
                    c.id,
                    Arc::new(ChannelInfo {
                        topic: c.topic,
                        type_name,
                        message_encoding: c.message_encoding,
                    }),
                );
            }
            Record::Message { header, data } => {
                let MessageHeader { channel_id, .. } = header;
                let Some(channel) = self.channels.get(&channel_id) else {
                    return Err(ChunkError::Layout(format!(
                        "a message of channel {channel_id}, which no channel record defines"
                    )));
                };
                if wanted(channel) {
                    visit(ScannedMessage {
                        channel,
                        location,
                        data: &data,
                    })
                    .map_err(ChunkError::Visit)?;
                }
            }
            _ => {}
        }
        Ok(())
    }
}
