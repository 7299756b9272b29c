//! Frames on the wire: the DCCL message `goby.position.protobuf.PositionFrame`
//! whose repeated `sample` field is coded by the user field codec
//! `goby.position` (this module), so frames travel through the stack like
//! any DCCL message.
//!
//! A frame is DCCL's identifier byte, a 10-bit sample count and the
//! samples' arithmetic codes back to back (see [`crate::sample_coder`]),
//! padded to a whole byte. The codec is stateful: its sender side advances
//! with every encoded frame, its receiver side with every decoded frame, so
//! frames must be delivered complete, in order and without duplicates (the
//! thesis assumes an ARQ link layer). [`PositionSender`] and
//! [`PositionReceiver`] are the API a vehicle program and a topside use.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, PoisonError};

use dccl::field::{BitReader, BitWriter, DecodeContext, EncodeContext, RepeatBounds};
use dccl::prost_reflect::{DynamicMessage, Kind, MessageDescriptor, ReflectMessage, Value};
use dccl::{CodecError, CodecRegistry, FieldCodec, FieldSpec};

use crate::config::PositionConfig;
use crate::error::PositionError;
use crate::sample_coder::{Sample, SampleCoder};

/// The frame definitions (`.proto` source).
pub const FRAME_PROTO: &str = include_str!("../proto/goby/position/position.proto");
/// Name under which the field codec is registered.
pub const CODEC_NAME: &str = "goby.position";
/// Full name of the frame message.
pub const FRAME_MESSAGE: &str = "goby.position.protobuf.PositionFrame";
/// Full name of the sample message.
pub const SAMPLE_MESSAGE: &str = "goby.position.protobuf.PositionSample";
/// Largest frame (the message's `max_bytes`).
pub const MAX_FRAME_BYTES: usize = 256;
/// Most samples in one frame (the field's `max_repeat`).
pub const MAX_FRAME_SAMPLES: usize = 1023;
/// Bits of DCCL's identifier (id 126: one byte).
const ID_BITS: usize = 8;
/// Bits of the sample count (`max_repeat` 1023).
const COUNT_BITS: usize = 10;
/// Sample bits one frame can hold.
const SAMPLE_BUDGET_BITS: usize = (MAX_FRAME_BYTES - ID_BITS / 8) * 8 - COUNT_BITS;

/// Bytes of a frame whose samples take `sample_bits` bits in all.
pub fn frame_bytes(sample_bits: usize) -> usize {
    ID_BITS / 8 + (COUNT_BITS + sample_bits).div_ceil(8)
}

/// The sender's and the receiver's coding state, shared with the field codec.
#[derive(Debug)]
struct Ends {
    encoder: Mutex<SampleCoder>,
    decoder: Mutex<SampleCoder>,
}

fn lock(m: &Mutex<SampleCoder>) -> std::sync::MutexGuard<'_, SampleCoder> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The `goby.position` field codec (repeated `PositionSample` fields only).
#[derive(Debug)]
struct PositionFieldCodec {
    ends: Arc<Ends>,
    version: i32,
    /// `PositionSample`, the field's type.
    sample: MessageDescriptor,
}

fn sample_of(value: &Value) -> Result<Sample, CodecError> {
    let Value::Message(m) = value else {
        return Err(CodecError::new("expected a PositionSample"));
    };
    let get = |name: &str| {
        m.get_field_by_name(name)
            .and_then(|v| v.as_f64())
            .ok_or_else(|| CodecError::new(format!("PositionSample without `{name}`")))
    };
    Ok(Sample {
        t: get("t")?,
        position: [get("x")?, get("y")?, get("z")?],
    })
}

fn value_of(desc: &MessageDescriptor, s: &Sample) -> Value {
    let mut m = DynamicMessage::new(desc.clone());
    m.set_field_by_name("t", Value::F64(s.t));
    for (name, v) in ["x", "y", "z"].iter().zip(s.position) {
        m.set_field_by_name(name, Value::F64(v));
    }
    Value::Message(m)
}

impl FieldCodec for PositionFieldCodec {
    fn name(&self) -> &str {
        CODEC_NAME
    }
    fn codec_version(&self) -> i32 {
        self.version
    }
    fn min_size(&self) -> u32 {
        0
    }
    fn max_size(&self) -> u32 {
        SAMPLE_BUDGET_BITS as u32
    }
    fn encode(
        &self,
        _out: &mut BitWriter,
        _value: Option<&Value>,
        _ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        Err(CodecError::new(
            "goby.position codes repeated PositionSample fields only",
        ))
    }
    fn decode(
        &self,
        _input: &mut BitReader<'_>,
        _ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Err(CodecError::new(
            "goby.position codes repeated PositionSample fields only",
        ))
    }
    fn encode_repeated(
        &self,
        out: &mut BitWriter,
        values: &[Value],
        bounds: RepeatBounds,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        if values.len() > bounds.max as usize {
            return Err(CodecError::new(format!(
                "{} samples exceed max_repeat {}",
                values.len(),
                bounds.max
            )));
        }
        let samples = values
            .iter()
            .map(sample_of)
            .collect::<Result<Vec<_>, _>>()?;
        let mut guard = lock(&self.ends.encoder);
        // A dry run (size only) codes on a copy and leaves the state as it is;
        // a failed encode leaves it as it is too.
        let mut coder = guard.clone();
        let mut body = BitWriter::new();
        for s in &samples {
            coder
                .encode(s, &mut body)
                .map_err(|e| CodecError::new(e.to_string()))?;
        }
        if body.len() > SAMPLE_BUDGET_BITS {
            return Err(CodecError::new(format!(
                "{} samples take {} bits, more than the frame's {SAMPLE_BUDGET_BITS}",
                samples.len(),
                body.len()
            )));
        }
        out.write(samples.len() as u64, bounds.prefix_bits());
        out.append(&body);
        if !ctx.dry_run {
            *guard = coder;
        }
        Ok(())
    }
    fn decode_repeated(
        &self,
        input: &mut BitReader<'_>,
        bounds: RepeatBounds,
        _ctx: &DecodeContext,
    ) -> Result<Vec<Value>, CodecError> {
        let count = input.read(bounds.prefix_bits())? as usize;
        let mut guard = lock(&self.ends.decoder);
        let mut coder = guard.clone();
        let mut out = Vec::with_capacity(count);
        for _ in 0..count {
            let (_, s) = coder
                .decode(input)
                .map_err(|e| CodecError::new(e.to_string()))?;
            out.push(value_of(&self.sample, &s));
        }
        *guard = coder;
        Ok(out)
    }
    fn min_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        bounds.prefix_bits()
    }
    fn max_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        bounds.prefix_bits() + SAMPLE_BUDGET_BITS as u32
    }
}

fn frame_pool() -> Result<dccl::prost_reflect::DescriptorPool, PositionError> {
    Ok(dccl::compile_sources(&[(
        "goby/position/position.proto",
        FRAME_PROTO,
    )])?)
}

/// Registers the `goby.position` codec in `registry`, coding with `config`;
/// returns the state it shares with the sender and receiver.
fn register(
    registry: &mut CodecRegistry,
    config: &PositionConfig,
) -> Result<Arc<Ends>, PositionError> {
    let ends = Arc::new(Ends {
        encoder: Mutex::new(SampleCoder::new(config.clone())?),
        decoder: Mutex::new(SampleCoder::new(config.clone())?),
    });
    let shared = ends.clone();
    registry.register(CODEC_NAME, move |spec: &FieldSpec<'_>| {
        let sample = match &spec.kind {
            Kind::Message(m) if m.full_name() == SAMPLE_MESSAGE => m.clone(),
            _ => return Ok(None),
        };
        let repeated = spec.field.map(|f| f.is_list()).unwrap_or(false);
        if !repeated {
            return Err(CodecError::new(
                "goby.position codes repeated PositionSample fields only",
            ));
        }
        Ok(Some(Arc::new(PositionFieldCodec {
            ends: shared.clone(),
            version: spec.codec_version,
            sample,
        }) as Arc<dyn FieldCodec>))
    });
    Ok(ends)
}

/// A DCCL codec with `PositionFrame` loaded and its coding state.
fn frame_codec(
    config: &PositionConfig,
) -> Result<(dccl::Codec, Arc<Ends>, MessageDescriptor), PositionError> {
    let mut registry = CodecRegistry::with_builtin();
    let ends = register(&mut registry, config)?;
    let mut codec = dccl::Codec::with_registry(registry);
    let pool = frame_pool()?;
    let frame = pool
        .get_message_by_name(FRAME_MESSAGE)
        .ok_or_else(|| PositionError::Frame(format!("{FRAME_MESSAGE} missing")))?;
    codec.load(&frame)?;
    Ok((codec, ends, frame))
}

/// The vehicle's end: push positions as they are measured, take frames to send.
#[derive(Debug)]
pub struct PositionSender {
    codec: dccl::Codec,
    ends: Arc<Ends>,
    frame: MessageDescriptor,
    sample: MessageDescriptor,
    pending: VecDeque<Sample>,
}

impl PositionSender {
    /// A sender with `config` (the receiver must use the same).
    pub fn new(config: PositionConfig) -> Result<Self, PositionError> {
        let (codec, ends, frame) = frame_codec(&config)?;
        let sample = frame
            .get_field_by_name("sample")
            .and_then(|f| f.kind().as_message().cloned())
            .ok_or_else(|| PositionError::Frame(format!("{FRAME_MESSAGE} without samples")))?;
        Ok(PositionSender {
            codec,
            ends,
            frame,
            sample,
            pending: VecDeque::new(),
        })
    }

    /// Queues a sample (one per sample period; a sample off the period's
    /// grid or after a gap goes as a full transmission). Fails, queuing
    /// nothing, when the sample is outside the configured bounds.
    pub fn push(&mut self, sample: Sample) -> Result<(), PositionError> {
        lock(&self.ends.encoder).quantize(&sample)?;
        self.pending.push_back(sample);
        Ok(())
    }

    /// Samples not yet in a frame.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Codes as many queued samples as fit in `max_bytes` (at most
    /// [`MAX_FRAME_BYTES`]) into the next frame; `None` when nothing is queued.
    /// Frames must be delivered in the order they are returned.
    pub fn next_frame(&mut self, max_bytes: usize) -> Result<Option<Vec<u8>>, PositionError> {
        if self.pending.is_empty() {
            return Ok(None);
        }
        let max_bytes = max_bytes.min(MAX_FRAME_BYTES);
        let mut trial = lock(&self.ends.encoder).clone();
        let mut bits = 0usize;
        let mut count = 0usize;
        for s in &self.pending {
            let mut w = BitWriter::new();
            trial.encode(s, &mut w)?;
            if frame_bytes(bits + w.len()) > max_bytes || count == MAX_FRAME_SAMPLES {
                break;
            }
            bits += w.len();
            count += 1;
        }
        if count == 0 {
            return Err(PositionError::Frame(format!(
                "{max_bytes} bytes cannot hold the next sample"
            )));
        }
        let mut msg = DynamicMessage::new(self.frame.clone());
        let values: Vec<Value> = self
            .pending
            .iter()
            .take(count)
            .map(|s| value_of(&self.sample, s))
            .collect();
        msg.set_field_by_name("sample", Value::List(values));
        let bytes = self.codec.encode(&msg)?;
        self.pending.drain(..count);
        Ok(Some(bytes))
    }
}

/// The topside's end: feed frames in order, get the samples back.
#[derive(Debug)]
pub struct PositionReceiver {
    codec: dccl::Codec,
}

impl PositionReceiver {
    /// A receiver with `config` (the sender's).
    pub fn new(config: PositionConfig) -> Result<Self, PositionError> {
        let (codec, _ends, _frame) = frame_codec(&config)?;
        Ok(PositionReceiver { codec })
    }

    /// Decodes the next frame. A frame that does not decode (truncated,
    /// corrupt) changes nothing, so a good copy of it can follow; a frame
    /// skipped or decoded twice puts the receiver out of step with the
    /// sender (its samples come out wrong), so the link must deliver every
    /// frame once, in order.
    pub fn receive(&mut self, frame: &[u8]) -> Result<Vec<Sample>, PositionError> {
        let msg = self.codec.decode(frame)?;
        if msg.descriptor().full_name() != FRAME_MESSAGE {
            return Err(PositionError::Frame(format!(
                "expected {FRAME_MESSAGE}, got {}",
                msg.descriptor().full_name()
            )));
        }
        let mut out = Vec::new();
        if let Some(list) = msg.get_field_by_name("sample") {
            if let Some(values) = list.as_list() {
                for v in values {
                    out.push(sample_of(v)?);
                }
            }
        }
        Ok(out)
    }
}
