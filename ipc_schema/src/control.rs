use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::payload::{check_total, section_len, PayloadReader, PayloadWriter};
use crate::{MessageKind, SchemaError, Stamp};

/// Largest control text (request argument or JSON reply).
pub const MAX_CONTROL_TEXT: u64 = 1 << 20;

/// Control commands from `opengs ctl` to the supervisor, and replies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ControlCommand {
    Status = 1,
    Stop = 2,
    /// Payload: `STAGE KIND`, e.g. `segmenter prior`.
    Swap = 3,
    /// Payload: `STAGE N`, e.g. `segmenter 4`: run N replicas of the stage.
    Scale = 4,
    /// Supervisor → ctl. Payload: JSON text.
    Reply = 100,
}

impl ControlCommand {
    pub fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            1 => Self::Status,
            2 => Self::Stop,
            3 => Self::Swap,
            4 => Self::Scale,
            100 => Self::Reply,
            _ => return None,
        })
    }
}

/// A control request or reply. Payload: UTF-8 text.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, bytemuck::Pod, bytemuck::Zeroable)]
#[type_name("opengs::ControlHeader")]
#[repr(C)]
pub struct ControlHeader {
    pub stamp: Stamp,
    pub command: u32,
    /// Replies carry 1 for success, 0 for failure.
    pub ok: u32,
    /// Chosen by the requester; the reply echoes it.
    pub request_id: u64,
    pub text_len: u64,
}

/// A control message, decoded.
#[derive(Debug, PartialEq)]
pub struct ControlView<'a> {
    pub command: ControlCommand,
    pub ok: bool,
    pub request_id: u64,
    pub text: &'a str,
}

/// Alias for readability at call sites that build requests.
pub type ControlRequest = ControlHeader;

impl ControlHeader {
    pub fn new(command: ControlCommand, request_id: u64, ok: bool, text: &str) -> Self {
        let mut stamp = Stamp::new(MessageKind::Control, 0, 0, 0);
        stamp.payload_len = section_len::<u8>(text.len()) as u64;
        Self {
            stamp,
            command: command as u32,
            ok: ok as u32,
            request_id,
            text_len: text.len() as u64,
        }
    }

    pub fn payload_len(&self) -> usize {
        self.stamp.payload_len as usize
    }

    pub fn encode(&self, text: &str, buf: &mut [MaybeUninit<u8>]) -> Result<(), SchemaError> {
        if text.len() as u64 != self.text_len {
            return Err(SchemaError::Invalid(
                "control text does not match the header",
            ));
        }
        check_total(self.payload_len(), buf.len())?;
        let mut w = PayloadWriter::new(buf);
        w.put(text.as_bytes())?;
        w.finish()
    }

    pub fn decode<'a>(&self, payload: &'a [u8]) -> Result<ControlView<'a>, SchemaError> {
        self.stamp.validate(MessageKind::Control, payload.len())?;
        if self.text_len > MAX_CONTROL_TEXT {
            return Err(SchemaError::Count {
                what: "text_len",
                value: self.text_len,
            });
        }
        check_total(section_len::<u8>(self.text_len as usize), payload.len())?;
        let command = ControlCommand::from_u32(self.command)
            .ok_or(SchemaError::Invalid("unknown control command"))?;
        let mut r = PayloadReader::new(payload)?;
        let bytes = r.take::<u8>(self.text_len as usize)?;
        let text = std::str::from_utf8(bytes)
            .map_err(|_| SchemaError::Invalid("control text is not UTF-8"))?;
        Ok(ControlView {
            command,
            ok: self.ok != 0,
            request_id: self.request_id,
            text,
        })
    }
}
