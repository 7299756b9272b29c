//! Arithmetic codec (`dccl.arithmetic`), bit for bit that of libdccl 4:
//! integer arithmetic coding (Witten, Neal and Cleary, 1987) with 32-bit code
//! values, driven by a probability model registered by name on the codec
//! (`dccl.arith.protobuf.ArithmeticModel`) and selected by the field option
//! `[(dccl.field) = { codec: "dccl.arithmetic" [arithmetic] { model: "name" } }]`.
//!
//! A model maps values to symbols (`value_bound`), gives each symbol a
//! frequency, and has two special symbols: end-of-array (ends a repeated
//! field shorter than `max_repeat`, or stands for an absent optional field)
//! and out-of-range (any value outside the bounds). Adaptive models add one
//! to a symbol's frequency each time it is coded; the sender's and the
//! receiver's copies therefore stay in step only if every message is decoded
//! in the order it was encoded.
//!
//! The models are definitions, registered on a [`Codec`](crate::Codec) and
//! never changed by coding. What adaptive coding changes, the frequencies
//! each model has reached, is an [`ArithmeticState`] owned by the `Codec`
//! (a clone of the codec gets its own copy): the `Codec` lends it to the
//! field codecs through the encode and decode contexts for the length of
//! one message and keeps the changes only when the whole message was
//! encoded (or decoded) for real, not for a size or a check, not on an error.
//!
//! The decoder starts from the field's minimum size and reads one more bit
//! only while the next symbol is ambiguous, so it reads exactly the bits the
//! encoder wrote and the fields after it decode correctly.
//!
//! Where libdccl's behaviour is undefined, this codec differs on purpose:
//! a value outside the model's bounds is coded with the out-of-range symbol
//! when the model gives it a frequency, and is an error otherwise; the
//! out-of-range symbol decodes as NaN for `double`/`float` fields and as
//! "not present" for other types; values nearest to the top bound are coded
//! with the last symbol; with `eof_frequency: 0`, arrays shorter
//! than `max_repeat` are filled up with the most probable symbol.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use prost_reflect::{EnumDescriptor, Kind, Value};

use crate::bits::{BitReader, BitWriter};
use crate::error::CodecError;
use crate::field_codec::{DecodeContext, EncodeContext, FieldCodec, FieldSpec, RepeatBounds};
use crate::registry::CodecRegistry;

pub use protos::dccl::arith::protobuf::ArithmeticModel;

/// Name under which the codec is registered.
pub const NAME: &str = "dccl.arithmetic";
/// Full name of the field option extension (number 1001 of `dccl.DCCLFieldOptions`).
pub const OPTION_EXTENSION: &str = "arithmetic";

const CODE_VALUE_BITS: u32 = 32;
const TOP_VALUE: u64 = (1 << CODE_VALUE_BITS) - 1;
const HALF: u64 = 1 << (CODE_VALUE_BITS - 1);
const FIRST_QTR: u64 = HALF >> 1;
const THIRD_QTR: u64 = HALF + FIRST_QTR;
/// Largest allowed sum of a model's frequencies (keeps products within 64 bits).
pub const MAX_FREQUENCY: u64 = (1 << (CODE_VALUE_BITS - 2)) - 1;

/// A symbol: `EOF_SYMBOL`, `OUT_OF_RANGE_SYMBOL` or an index into `frequency`.
type Symbol = i64;
const EOF_SYMBOL: Symbol = -2;
const OUT_OF_RANGE_SYMBOL: Symbol = -1;

/// The field option (`[arithmetic] { model: "..." }`).
#[derive(Clone, PartialEq, prost::Message)]
struct ArithmeticOptions {
    #[prost(string, optional, tag = "1")]
    model: Option<String>,
    #[prost(bool, optional, tag = "2")]
    debug_assert: Option<bool>,
}

/// Cumulative frequencies, indexed by `symbol - EOF_SYMBOL`: entry `i` is the
/// sum of the frequencies of every symbol up to and including symbol `i`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Cumulative(Vec<u64>);

impl Cumulative {
    /// The coder's symbol index of a model symbol.
    fn index(symbol: Symbol) -> usize {
        (symbol - EOF_SYMBOL) as usize
    }

    /// Adaptive update: one more occurrence of `symbol`.
    fn update(&mut self, symbol: Symbol) {
        let start = (symbol - EOF_SYMBOL) as usize;
        for c in &mut self.0[start..] {
            *c += 1;
        }
    }
}

/// A validated model: the definition and its initial frequencies, never
/// changed by coding (adaptive frequencies live in an [`ArithmeticState`]).
#[derive(Debug)]
pub(crate) struct Model {
    user: ArithmeticModel,
    initial: Cumulative,
}

fn invalid(model: &ArithmeticModel, reason: &str) -> CodecError {
    CodecError::new(format!(
        "invalid arithmetic model `{}`: {reason}",
        model.name
    ))
}

impl Model {
    /// Validates a model as libdccl does.
    pub(crate) fn new(user: ArithmeticModel) -> Result<Model, CodecError> {
        if user.name.is_empty() {
            return Err(invalid(&user, "missing required field `name`"));
        }
        if user.frequency.is_empty() {
            return Err(invalid(&user, "no symbol (`frequency` is empty)"));
        }
        if user.frequency.contains(&0) {
            return Err(invalid(&user, "all frequencies must be nonzero"));
        }
        let mut cumulative = Vec::with_capacity(user.frequency.len() + 2);
        let mut sum = 0u64;
        for f in [user.eof_frequency(), user.out_of_range_frequency()]
            .into_iter()
            .chain(user.frequency.iter().copied())
        {
            sum += f as u64;
            cumulative.push(sum);
        }
        if sum > MAX_FREQUENCY {
            return Err(invalid(
                &user,
                &format!("sum of all frequencies must be less than {MAX_FREQUENCY}"),
            ));
        }
        if user.value_bound.len() != user.frequency.len() + 1 {
            return Err(invalid(
                &user,
                "`value_bound` size must be exactly 1 more than number of symbols (= size of \
                 `frequency`)",
            ));
        }
        if user.value_bound.iter().any(|b| b.is_nan())
            || user.value_bound.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(invalid(&user, "`value_bound` must be strictly increasing"));
        }
        Ok(Model {
            initial: Cumulative(cumulative),
            user,
        })
    }

    /// The model as the user gave it.
    pub(crate) fn user_model(&self) -> &ArithmeticModel {
        &self.user
    }

    /// The symbol of a value (out-of-range symbol when outside the bounds).
    fn value_to_symbol(&self, value: f64) -> Symbol {
        let bounds = &self.user.value_bound;
        let (first, last) = (bounds[0], bounds[bounds.len() - 1]);
        if value.is_nan() || value < first || value > last {
            return OUT_OF_RANGE_SYMBOL;
        }
        // Nearest of the two surrounding bounds, compared as libdccl does
        // (on the squares of the values).
        let upper = bounds.partition_point(|b| *b <= value);
        let lower = upper.saturating_sub(1);
        let symbol = match bounds.get(upper) {
            Some(up) => {
                let lower_diff = (bounds[lower] * bounds[lower] - value * value).abs();
                let upper_diff = (up * up - value * value).abs();
                if lower_diff < upper_diff {
                    lower
                } else {
                    upper
                }
            }
            None => lower,
        };
        // The top bound itself has no symbol of its own (libdccl's behaviour
        // is undefined there): values nearest to it belong to the last symbol.
        symbol.min(self.user.frequency.len() - 1) as Symbol
    }

    fn symbol_to_value(&self, symbol: Symbol) -> f64 {
        if symbol == OUT_OF_RANGE_SYMBOL {
            f64::NAN
        } else {
            self.user.value_bound[symbol as usize]
        }
    }

    /// The most probable value symbol (first of equals).
    fn most_probable_symbol(&self) -> Symbol {
        let mut best = 0;
        for (i, f) in self.user.frequency.iter().enumerate() {
            if *f > self.user.frequency[best] {
                best = i;
            }
        }
        best as Symbol
    }

    /// Largest size in bits of `max_repeat` values (libdccl's bound:
    /// `ceil(log2(1/P)) + 1` for the least probable sequence).
    fn max_size(&self, max_repeat: u32) -> u32 {
        let total = (self.initial.total() as f64).log2();
        let oor = match self.user.out_of_range_frequency() {
            0 => MAX_FREQUENCY as u32,
            f => f,
        };
        let lowest = oor.min(*self.user.frequency.iter().min().unwrap_or(&1)) as f64;
        let n = max_repeat as f64;
        let least_probable = (n * (total - lowest.log2())).ceil() as u32;
        let eof = self.user.eof_frequency();
        let least_probable_plus_eof = if eof != 0 {
            (n * total - (n - 1.0) * lowest.log2() - (eof as f64).log2()).ceil() as u32
        } else {
            0
        };
        least_probable_plus_eof
            .max(least_probable)
            .saturating_add(1)
    }

    /// Smallest size in bits (0 for adaptive models: the decoder then looks
    /// at the bits from the first one).
    fn min_size(&self, max_repeat: u32) -> u32 {
        if self.user.is_adaptive() {
            return 0;
        }
        let total = (self.initial.total() as f64).log2();
        let oor = self.user.out_of_range_frequency().max(1);
        let eof = self.user.eof_frequency();
        let empty = if eof != 0 {
            (total - (eof as f64).log2()).ceil() as u32
        } else {
            u32::MAX
        };
        let highest = oor.max(*self.user.frequency.iter().max().unwrap_or(&1)) as f64;
        let most_probable = (max_repeat as f64 * (total - highest.log2())).ceil() as u32;
        empty.min(most_probable)
    }

    /// Encodes up to `max_repeat` values (fewer: followed by the end-of-array
    /// symbol) with the frequencies `adaptive` has reached (advanced symbol
    /// by symbol), or with the initial ones when the model is not adaptive
    /// (`adaptive` is then `None`).
    fn encode(
        &self,
        out: &mut BitWriter,
        values: &[f64],
        max_repeat: u32,
        mut adaptive: Option<&mut Cumulative>,
    ) -> Result<(), CodecError> {
        let mut coder = ArithmeticEncoder::new();
        for index in 0..max_repeat as usize {
            let mut symbol = match values.get(index) {
                Some(v) => self.value_to_symbol(*v),
                None => EOF_SYMBOL,
            };
            if symbol == OUT_OF_RANGE_SYMBOL && self.user.out_of_range_frequency() == 0 {
                return Err(CodecError::new(format!(
                    "value {} is outside the bounds [{}, {}] of arithmetic model `{}`, \
                     which has no out-of-range symbol (out_of_range_frequency: 0)",
                    values[index],
                    self.user.value_bound[0],
                    self.user.value_bound[self.user.value_bound.len() - 1],
                    self.user.name
                )));
            }
            if symbol == EOF_SYMBOL && self.user.eof_frequency() == 0 {
                symbol = self.most_probable_symbol();
            }
            match adaptive.as_deref_mut() {
                Some(frequencies) => {
                    coder.encode(&*frequencies, Cumulative::index(symbol));
                    frequencies.update(symbol);
                }
                None => coder.encode(&self.initial, Cumulative::index(symbol)),
            }
            if index == values.len() && self.user.eof_frequency() != 0 {
                break;
            }
        }
        coder.finish(out);
        Ok(())
    }

    /// Decodes up to `max_repeat` values, reading `min_bits` bits first and
    /// then one bit at a time while the next symbol is ambiguous; the
    /// frequencies are those of [`Model::encode`].
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        max_repeat: u32,
        min_bits: u32,
        mut adaptive: Option<&mut Cumulative>,
    ) -> Result<Vec<f64>, CodecError> {
        let mut coder = ArithmeticDecoder::new(input, min_bits)?;
        let mut values = Vec::new();
        for _ in 0..max_repeat {
            let symbol = match adaptive.as_deref_mut() {
                Some(frequencies) => {
                    let symbol = coder.decode(input, &*frequencies)? as Symbol + EOF_SYMBOL;
                    frequencies.update(symbol);
                    symbol
                }
                None => coder.decode(input, &self.initial)? as Symbol + EOF_SYMBOL,
            };
            if symbol == EOF_SYMBOL {
                break;
            }
            values.push(self.symbol_to_value(symbol));
        }
        Ok(values)
    }
}

impl CumulativeFrequencies for Cumulative {
    fn symbol_count(&self) -> usize {
        self.0.len()
    }

    fn cumulative(&self, index: usize) -> u64 {
        self.0[index]
    }

    fn total(&self) -> u64 {
        self.0.last().copied().unwrap_or(0)
    }

    /// libdccl's search, linear from the end-of-array symbol; when no symbol
    /// fits (a value past the total, from bits that belong to a later
    /// field), libdccl takes value symbol 0.
    fn symbol_above(&self, frequency: u64) -> usize {
        self.0
            .iter()
            .position(|&c| frequency < c)
            .unwrap_or(Self::index(0))
    }
}

/// A probability model as the integer arithmetic coder sees it: symbols
/// `0..symbol_count()` with cumulative frequencies.
///
/// This is the coder core that the `dccl.arithmetic` codec runs on, open to
/// codecs that compute their models themselves (for example a distribution
/// that changes from one symbol to the next). Frequencies must be nonzero
/// for every symbol that is coded, and the total must not exceed
/// [`MAX_FREQUENCY`].
pub trait CumulativeFrequencies {
    /// Number of symbols.
    fn symbol_count(&self) -> usize;

    /// Sum of the frequencies of symbols `0..=index`.
    fn cumulative(&self, index: usize) -> u64;

    /// Sum of all frequencies.
    fn total(&self) -> u64 {
        self.cumulative(self.symbol_count() - 1)
    }

    /// The first symbol whose cumulative frequency exceeds `frequency` (the
    /// last symbol when none does).
    fn symbol_above(&self, frequency: u64) -> usize {
        let (mut lo, mut hi) = (0, self.symbol_count() - 1);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.cumulative(mid) > frequency {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        lo
    }
}

/// A model given as a table of symbol frequencies.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrequencyTable {
    cumulative: Vec<u64>,
}

impl FrequencyTable {
    /// The table of `frequencies` (symbol `i` has frequency `frequencies[i]`).
    /// Fails when there is no symbol, a frequency is zero, or the total
    /// exceeds [`MAX_FREQUENCY`].
    pub fn new(frequencies: &[u64]) -> Result<FrequencyTable, CodecError> {
        if frequencies.is_empty() {
            return Err(CodecError::new("frequency table without symbols"));
        }
        if frequencies.contains(&0) {
            return Err(CodecError::new("frequency table with a zero frequency"));
        }
        let mut cumulative = Vec::with_capacity(frequencies.len());
        let mut sum = 0u64;
        for f in frequencies {
            sum = sum.saturating_add(*f);
            cumulative.push(sum);
        }
        if sum > MAX_FREQUENCY {
            return Err(CodecError::new(format!(
                "frequency table total {sum} exceeds {MAX_FREQUENCY}"
            )));
        }
        Ok(FrequencyTable { cumulative })
    }

    /// The frequency of one symbol.
    pub fn frequency(&self, index: usize) -> u64 {
        match index {
            0 => self.cumulative[0],
            i => self.cumulative[i] - self.cumulative[i - 1],
        }
    }
}

impl CumulativeFrequencies for FrequencyTable {
    fn symbol_count(&self) -> usize {
        self.cumulative.len()
    }

    fn cumulative(&self, index: usize) -> u64 {
        self.cumulative[index]
    }

    fn total(&self) -> u64 {
        self.cumulative[self.cumulative.len() - 1]
    }
}

/// Encodes a sequence of symbols, each with its own model, into the fewest
/// bits that identify it (the integer coder of Witten, Neal and Cleary with
/// 32-bit code values, ended as libdccl ends it).
///
/// ```
/// use dccl::field::{ArithmeticDecoder, ArithmeticEncoder, BitReader, BitWriter, FrequencyTable};
///
/// let table = FrequencyTable::new(&[1, 6, 1])?;
/// let mut encoder = ArithmeticEncoder::new();
/// for symbol in [1, 1, 2, 1] {
///     encoder.encode(&table, symbol);
/// }
/// let mut out = BitWriter::new();
/// encoder.finish(&mut out);
/// out.write(5, 3); // whatever follows
///
/// let bytes = out.into_bytes();
/// let mut input = BitReader::new(&bytes);
/// let mut decoder = ArithmeticDecoder::new(&mut input, 0)?;
/// let symbols: Vec<usize> = (0..4)
///     .map(|_| decoder.decode(&mut input, &table))
///     .collect::<Result<_, _>>()?;
/// assert_eq!(symbols, [1, 1, 2, 1]);
/// assert_eq!(input.read(3)?, 5); // the decoder read exactly the coded bits
/// # Ok::<(), dccl::CodecError>(())
/// ```
#[derive(Debug, Clone)]
pub struct ArithmeticEncoder {
    low: u64,
    high: u64,
    follow: u32,
    bits: Vec<bool>,
}

impl Default for ArithmeticEncoder {
    fn default() -> Self {
        Self::new()
    }
}

impl ArithmeticEncoder {
    /// An encoder with the full interval.
    pub fn new() -> Self {
        ArithmeticEncoder {
            low: 0,
            high: TOP_VALUE,
            follow: 0,
            bits: Vec::new(),
        }
    }

    /// Narrows the interval to symbol `index` of `table`.
    ///
    /// # Panics
    /// When `index` is not a symbol of `table` or its frequency is zero.
    pub fn encode<T: CumulativeFrequencies + ?Sized>(&mut self, table: &T, index: usize) {
        let range = self.high - self.low + 1;
        let c_low = if index == 0 {
            0
        } else {
            table.cumulative(index - 1)
        };
        let c_high = table.cumulative(index);
        let total = table.total();
        self.high = self.low + (range * c_high) / total - 1;
        self.low += (range * c_low) / total;
        loop {
            if self.high < HALF {
                self.emit(false);
            } else if self.low >= HALF {
                self.emit(true);
                self.low -= HALF;
                self.high -= HALF;
            } else if self.low >= FIRST_QTR && self.high < THIRD_QTR {
                self.follow += 1;
                self.low -= FIRST_QTR;
                self.high -= FIRST_QTR;
            } else {
                break;
            }
            self.low <<= 1;
            self.high = (self.high << 1) + 1;
        }
    }

    fn emit(&mut self, bit: bool) {
        self.bits.push(bit);
        while self.follow > 0 {
            self.bits.push(!bit);
            self.follow -= 1;
        }
    }

    /// Ends the code with the fewest bits that pin the final interval down
    /// and writes every bit to `out`.
    pub fn finish(mut self, out: &mut BitWriter) {
        if self.low == 0 {
            if self.high != TOP_VALUE || self.follow > 0 {
                self.emit(false);
            }
        } else if self.high == TOP_VALUE {
            self.emit(true);
        } else {
            self.follow += 1;
            let bit = self.low >= FIRST_QTR;
            self.emit(bit);
        }
        for bit in self.bits {
            out.write_bool(bit);
        }
    }
}

/// Decodes what an [`ArithmeticEncoder`] wrote, reading one bit at a time
/// only while the next symbol is ambiguous, so that it consumes exactly the
/// encoder's bits and whatever follows them stays in place.
#[derive(Debug, Clone)]
pub struct ArithmeticDecoder {
    value: u64,
    /// Low bits of `value` not read yet (negative: more read than used).
    unknown: i64,
    low: u64,
    high: u64,
}

impl ArithmeticDecoder {
    /// Starts decoding, reading `min_bits` bits at once (0 is always safe;
    /// more is allowed only when every code is at least that long).
    pub fn new(input: &mut BitReader<'_>, min_bits: u32) -> Result<Self, CodecError> {
        let mut value = 0u64;
        for i in 0..min_bits {
            let bit = input.read_bool()?;
            if i < CODE_VALUE_BITS && bit {
                value |= 1 << (CODE_VALUE_BITS - 1 - i);
            }
        }
        Ok(ArithmeticDecoder {
            value,
            unknown: CODE_VALUE_BITS as i64 - min_bits as i64,
            low: 0,
            high: TOP_VALUE,
        })
    }

    /// Decodes the next symbol, which the encoder coded with `table`.
    pub fn decode<T: CumulativeFrequencies + ?Sized>(
        &mut self,
        input: &mut BitReader<'_>,
        table: &T,
    ) -> Result<usize, CodecError> {
        let range = self.high - self.low + 1;
        let total = table.total();
        let last = table.symbol_count() - 1;
        let index = loop {
            let value_high = if self.unknown > 0 {
                self.value.wrapping_add((1u64 << self.unknown.min(63)) - 1)
            } else {
                self.value
            };
            let c_low = (self.value.wrapping_sub(self.low).wrapping_add(1))
                .wrapping_mul(total)
                .wrapping_sub(1)
                / range;
            let c_high = (value_high.wrapping_sub(self.low).wrapping_add(1))
                .wrapping_mul(total)
                .wrapping_sub(1)
                / range;
            // libdccl keeps these in 32-bit unsigned integers.
            let (c_low, c_high) = (c_low as u32 as u64, c_high as u32 as u64);
            let first = table.symbol_above(c_low);
            if first == last || table.cumulative(first) > c_high {
                break first;
            }
            let bit = input.read_bool()?;
            self.unknown -= 1;
            if self.unknown >= 0 && bit {
                self.value |= 1 << self.unknown;
            }
        };
        let c_low = if index == 0 {
            0
        } else {
            table.cumulative(index - 1)
        };
        let c_high = table.cumulative(index);
        self.high = self.low + (range * c_high) / total - 1;
        self.low += (range * c_low) / total;
        loop {
            if self.high < HALF {
            } else if self.low >= HALF {
                self.value = self.value.wrapping_sub(HALF);
                self.low -= HALF;
                self.high -= HALF;
            } else if self.low >= FIRST_QTR && self.high < THIRD_QTR {
                self.value = self.value.wrapping_sub(FIRST_QTR);
                self.low -= FIRST_QTR;
                self.high -= FIRST_QTR;
            } else {
                break;
            }
            self.low <<= 1;
            self.high = (self.high << 1) + 1;
            self.value = self.value.wrapping_shl(1);
            self.unknown += 1;
        }
        Ok(index)
    }
}

/// The models of one codec, by name: definitions only, shared by every
/// field that uses them and cloned with the registry that holds them.
#[derive(Debug, Clone, Default)]
pub(crate) struct ArithmeticModels {
    models: HashMap<String, Arc<Model>>,
    /// Whether one of the models is adaptive.
    adaptive: bool,
}

impl ArithmeticModels {
    /// Validates and registers (or replaces) a model under its name.
    pub(crate) fn set(&mut self, model: ArithmeticModel) -> Result<(), CodecError> {
        let model = Model::new(model)?;
        self.models.insert(model.user.name.clone(), Arc::new(model));
        self.adaptive = self.models.values().any(|m| m.user.is_adaptive());
        Ok(())
    }

    /// Whether one of the models is adaptive: only then has a message
    /// frequencies to advance ([`ArithmeticSession`]).
    pub(crate) fn any_adaptive(&self) -> bool {
        self.adaptive
    }

    /// The model registered under `name`.
    pub(crate) fn get(&self, name: &str) -> Option<&Arc<Model>> {
        self.models.get(name)
    }
}

/// Which copy of an adaptive model's frequencies: the sender's or the receiver's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Direction {
    Encoder,
    Decoder,
}

/// The frequencies the adaptive arithmetic models of a [`Codec`](crate::Codec)
/// have reached: for each adaptive model, one copy advanced by encoding and
/// one by decoding (as libdccl keeps them), each starting from the model's
/// frequencies and adding one to a symbol's frequency each time the symbol
/// is coded.
///
/// A `Codec` owns its state and a clone of the codec starts with a copy of
/// it, advancing on its own. [`Codec::arithmetic_state`](crate::Codec::arithmetic_state)
/// takes a snapshot and [`Codec::set_arithmetic_state`](crate::Codec::set_arithmetic_state)
/// puts one back (for example to send a message again exactly as it was
/// sent, or to take back a message that was encoded but never sent);
/// `ArithmeticState::default()` is the state of a codec that has coded
/// nothing.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ArithmeticState {
    frequencies: BTreeMap<(String, Direction), Cumulative>,
}

impl ArithmeticState {
    /// True when no adaptive model has moved from its initial frequencies.
    pub fn is_initial(&self) -> bool {
        self.frequencies.is_empty()
    }

    /// Forgets what the adaptive model `name` has learnt (it was replaced).
    pub(crate) fn restart(&mut self, name: &str) {
        self.frequencies.retain(|(model, _), _| model != name);
    }

    /// Checks that every model of the state is an adaptive model of
    /// `models` with as many symbols; returns the name of one that is not.
    pub(crate) fn misfit(&self, models: &ArithmeticModels) -> Option<String> {
        self.frequencies
            .iter()
            .find(|((name, _), frequencies)| {
                !models.get(name).is_some_and(|m| {
                    m.user.is_adaptive() && m.initial.0.len() == frequencies.0.len()
                })
            })
            .map(|((name, _), _)| name.clone())
    }
}

/// A codec's [`ArithmeticState`] behind a lock (so that a `Codec` can be
/// shared between threads); a clone is a copy, not a share.
#[derive(Debug, Default)]
pub(crate) struct SharedState(Mutex<ArithmeticState>);

impl SharedState {
    pub(crate) fn lock(&self) -> MutexGuard<'_, ArithmeticState> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Clone for SharedState {
    fn clone(&self) -> Self {
        SharedState(Mutex::new(self.lock().clone()))
    }
}

/// The models and adaptive state lent to the field codecs while one message
/// is encoded or decoded. An adaptive model's frequencies are copied out of
/// the codec's state the first time the message uses them; the copies go
/// back with [`ArithmeticSession::finish`] when the message was coded for
/// real and without error.
#[derive(Debug)]
pub(crate) struct ArithmeticSession<'a> {
    models: &'a ArithmeticModels,
    state: &'a SharedState,
    /// False for a size or a check: the state is left as it is.
    keep: bool,
    working: RefCell<BTreeMap<(String, Direction), Cumulative>>,
}

impl<'a> ArithmeticSession<'a> {
    pub(crate) fn new(models: &'a ArithmeticModels, state: &'a SharedState, keep: bool) -> Self {
        ArithmeticSession {
            models,
            state,
            keep,
            working: RefCell::new(BTreeMap::new()),
        }
    }

    /// Runs `code` with the frequencies `model` has reached in `direction`
    /// during this message (`None` when the model is not adaptive).
    fn with_frequencies<R>(
        &self,
        model: &Model,
        direction: Direction,
        code: impl FnOnce(Option<&mut Cumulative>) -> R,
    ) -> R {
        if !model.user.is_adaptive() {
            return code(None);
        }
        let mut working = self.working.borrow_mut();
        let key = (model.user.name.clone(), direction);
        let frequencies = working.entry(key).or_insert_with_key(|key| {
            self.state
                .lock()
                .frequencies
                .get(key)
                .filter(|f| f.0.len() == model.initial.0.len())
                .cloned()
                .unwrap_or_else(|| model.initial.clone())
        });
        code(Some(frequencies))
    }

    /// Puts the frequencies this message advanced back into the codec's
    /// state, when the message was coded for real (`ok`: without error).
    pub(crate) fn finish(self, ok: bool) {
        let working = self.working.into_inner();
        if self.keep && ok && !working.is_empty() {
            self.state.lock().frequencies.extend(working);
        }
    }
}

/// Runs `code` with the frequencies of `model` in `direction`: those of the
/// message's session, or (no session: a codec called outside a `Codec`,
/// e.g. by [`FieldCodec::size`]) a copy of the initial ones of an adaptive model.
fn with_frequencies<R>(
    session: Option<&ArithmeticSession<'_>>,
    model: &Model,
    direction: Direction,
    code: impl FnOnce(Option<&mut Cumulative>) -> R,
) -> R {
    match session {
        Some(session) => session.with_frequencies(model, direction, code),
        None if model.user.is_adaptive() => code(Some(&mut model.initial.clone())),
        None => code(None),
    }
}

/// Parses models in protobuf text format, one `ArithmeticModel` per line
/// (blank lines and lines starting with `#` are skipped).
pub(crate) fn parse_models(text: &str) -> Result<Vec<ArithmeticModel>, CodecError> {
    let desc = protos::DESCRIPTOR_POOL
        .get_message_by_name("dccl.arith.protobuf.ArithmeticModel")
        .ok_or_else(|| CodecError::new("ArithmeticModel descriptor missing"))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let msg = prost_reflect::DynamicMessage::parse_text_format(desc.clone(), line)
            .map_err(|e| CodecError::new(format!("arithmetic model on line {}: {e}", n + 1)))?;
        let has_name = msg.has_field_by_name("name");
        let model: ArithmeticModel = msg
            .transcode_to()
            .map_err(|e| CodecError::new(format!("arithmetic model on line {}: {e}", n + 1)))?;
        if !has_name {
            return Err(CodecError::new(format!(
                "arithmetic model on line {}: missing required field `name`",
                n + 1
            )));
        }
        out.push(model);
    }
    Ok(out)
}

/// How field values map to the codec's `f64` values.
#[derive(Debug, Clone)]
enum FieldType {
    Int32,
    Int64,
    Uint32,
    Uint64,
    Double,
    Float,
    Bool,
    Enum(EnumDescriptor),
}

impl FieldType {
    fn of(kind: &Kind) -> Option<FieldType> {
        Some(match kind {
            Kind::Int32 | Kind::Sint32 | Kind::Sfixed32 => FieldType::Int32,
            Kind::Int64 | Kind::Sint64 | Kind::Sfixed64 => FieldType::Int64,
            Kind::Uint32 | Kind::Fixed32 => FieldType::Uint32,
            Kind::Uint64 | Kind::Fixed64 => FieldType::Uint64,
            Kind::Double => FieldType::Double,
            Kind::Float => FieldType::Float,
            Kind::Bool => FieldType::Bool,
            Kind::Enum(e) => FieldType::Enum(e.clone()),
            _ => return None,
        })
    }

    fn to_f64(&self, value: &Value) -> Result<f64, CodecError> {
        Ok(match value {
            Value::I32(x) => *x as f64,
            Value::I64(x) => *x as f64,
            Value::U32(x) => *x as f64,
            Value::U64(x) => *x as f64,
            Value::F64(x) => *x,
            Value::F32(x) => *x as f64,
            Value::Bool(b) => *b as u8 as f64,
            Value::EnumNumber(n) => *n as f64,
            other => {
                return Err(CodecError::new(format!(
                    "value {other:?} cannot be arithmetic coded"
                )))
            }
        })
    }

    /// The field value of a decoded number (`None`: not present).
    fn value_of(&self, v: f64) -> Option<Value> {
        if v.is_nan() {
            return match self {
                FieldType::Double => Some(Value::F64(v)),
                FieldType::Float => Some(Value::F32(v as f32)),
                _ => None,
            };
        }
        Some(match self {
            FieldType::Int32 => Value::I32(v as i32),
            FieldType::Int64 => Value::I64(v as i64),
            FieldType::Uint32 => Value::U32(v as u32),
            FieldType::Uint64 => Value::U64(v as u64),
            FieldType::Double => Value::F64(v),
            FieldType::Float => Value::F32(v as f32),
            FieldType::Bool => Value::Bool(v != 0.0),
            FieldType::Enum(e) => Value::EnumNumber(e.get_value(v as i32)?.number()),
        })
    }
}

/// The arithmetic field codec.
#[derive(Debug)]
pub(crate) struct ArithmeticCodec {
    name: String,
    version: i32,
    model_name: String,
    field_type: FieldType,
    /// Its model when the field was loaded (sizes are computed from it).
    loaded_model: Arc<Model>,
}

impl ArithmeticCodec {
    /// Creates the codec for a field, or `None` for types it cannot code
    /// (strings, bytes, messages). Fails when the option or the model is missing.
    pub(crate) fn create(
        spec: &FieldSpec<'_>,
        name: &str,
    ) -> Result<Option<Arc<dyn FieldCodec>>, CodecError> {
        let Some(field_type) = FieldType::of(&spec.kind) else {
            return Ok(None);
        };
        let options: ArithmeticOptions = spec
            .option_extension(OPTION_EXTENSION)?
            .ok_or_else(|| CodecError::new("missing (dccl.field).arithmetic"))?;
        let model_name = options
            .model
            .ok_or_else(|| CodecError::new("missing (dccl.field).arithmetic.model"))?;
        let loaded_model = spec
            .registry
            .arithmetic_models()
            .get(&model_name)
            .cloned()
            .ok_or_else(|| {
                CodecError::new(format!(
                    "no such (dccl.field).arithmetic.model called \"{model_name}\" loaded"
                ))
            })?;
        Ok(Some(Arc::new(ArithmeticCodec {
            name: name.to_string(),
            version: spec.codec_version,
            model_name,
            field_type,
            loaded_model,
        })))
    }

    /// The model now registered under the field's model name on the codec
    /// coding the message (else the one the field was loaded with).
    fn model<'s>(&'s self, session: Option<&'s ArithmeticSession<'_>>) -> &'s Model {
        session
            .and_then(|s| s.models.get(&self.model_name))
            .unwrap_or(&self.loaded_model)
    }

    fn encode_values(
        &self,
        out: &mut BitWriter,
        values: &[Value],
        max_repeat: u32,
        repeated: bool,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        let numbers = values
            .iter()
            .take(max_repeat as usize)
            .map(|v| self.field_type.to_f64(v))
            .collect::<Result<Vec<f64>, _>>()?;
        let model = self.model(ctx.arithmetic);
        if ctx.changes.is_some() && model.user.out_of_range_frequency() != 0 {
            let bounds = &model.user.value_bound;
            for (i, x) in numbers.iter().enumerate() {
                if model.value_to_symbol(*x) == OUT_OF_RANGE_SYMBOL {
                    let mark = ctx.change_mark();
                    ctx.note_change(
                        || {
                            format!(
                                "{x} is outside the bounds [{}, {}] of arithmetic model `{}`",
                                bounds[0],
                                bounds[bounds.len() - 1],
                                model.user.name
                            )
                        },
                        "sent as out of range (received as NaN)",
                    );
                    if repeated {
                        ctx.name_changes(mark, || format!("[{i}]"));
                    }
                }
            }
        }
        with_frequencies(ctx.arithmetic, model, Direction::Encoder, |adaptive| {
            model.encode(out, &numbers, max_repeat, adaptive)
        })
    }

    fn decode_values(
        &self,
        input: &mut BitReader<'_>,
        max_repeat: u32,
        ctx: &DecodeContext,
    ) -> Result<Vec<Value>, CodecError> {
        let model = self.model(ctx.arithmetic);
        let min_bits = model.min_size(max_repeat);
        let values = with_frequencies(ctx.arithmetic, model, Direction::Decoder, |adaptive| {
            model.decode(input, max_repeat, min_bits, adaptive)
        })?;
        Ok(values
            .into_iter()
            .filter_map(|v| self.field_type.value_of(v))
            .collect())
    }
}

impl FieldCodec for ArithmeticCodec {
    fn reads_clock(&self) -> bool {
        false
    }
    fn name(&self) -> &str {
        &self.name
    }
    fn codec_version(&self) -> i32 {
        self.version
    }
    fn min_size(&self) -> u32 {
        self.loaded_model.min_size(1)
    }
    fn max_size(&self) -> u32 {
        self.loaded_model.max_size(1)
    }
    fn encode(
        &self,
        out: &mut BitWriter,
        value: Option<&Value>,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        self.encode_values(
            out,
            value.map(std::slice::from_ref).unwrap_or(&[]),
            1,
            false,
            ctx,
        )
    }
    fn decode(
        &self,
        input: &mut BitReader<'_>,
        ctx: &DecodeContext,
    ) -> Result<Option<Value>, CodecError> {
        Ok(self.decode_values(input, 1, ctx)?.into_iter().next())
    }
    fn encode_repeated(
        &self,
        out: &mut BitWriter,
        values: &[Value],
        bounds: RepeatBounds,
        ctx: &EncodeContext,
    ) -> Result<(), CodecError> {
        bounds.check_max(values.len(), ctx)?;
        self.encode_values(out, values, bounds.max, true, ctx)
    }
    fn decode_repeated(
        &self,
        input: &mut BitReader<'_>,
        bounds: RepeatBounds,
        ctx: &DecodeContext,
    ) -> Result<Vec<Value>, CodecError> {
        self.decode_values(input, bounds.max, ctx)
    }
    fn min_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        self.loaded_model.min_size(bounds.max)
    }
    fn max_size_repeated(&self, bounds: RepeatBounds) -> u32 {
        self.loaded_model.max_size(bounds.max)
    }
}

/// Registers the codec as `dccl.arithmetic` (and libdccl's older name
/// `_arithmetic`, reported as written), its models taken from the registry
/// the field is built with.
pub(crate) fn register(registry: &mut CodecRegistry) {
    for name in [NAME, "_arithmetic"] {
        registry.register(name, move |spec: &FieldSpec<'_>| {
            ArithmeticCodec::create(spec, name)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The public coder over a frequency table writes the very bits the
    /// model-driven codec writes for the same frequencies.
    #[test]
    fn public_coder_matches_the_codec() {
        let model = Model::new(ArithmeticModel {
            name: "m".into(),
            frequency: vec![3, 1, 5, 2],
            value_bound: vec![0.0, 1.0, 2.0, 3.0, 4.0],
            eof_frequency: Some(1),
            out_of_range_frequency: Some(1),
            ..Default::default()
        })
        .unwrap();
        let values = [1.0, 3.0, 0.0, 2.0, 9.0];
        let mut by_model = BitWriter::new();
        model
            .encode(&mut by_model, &values, values.len() as u32, None)
            .unwrap();
        // Table order: end-of-array, out-of-range, then the values.
        let table = FrequencyTable::new(&[1, 1, 3, 1, 5, 2]).unwrap();
        let mut coder = ArithmeticEncoder::new();
        for symbol in [3, 5, 2, 4, 1] {
            coder.encode(&table, symbol);
        }
        let mut by_table = BitWriter::new();
        coder.finish(&mut by_table);
        assert_eq!(by_model.len(), by_table.len());
        assert_eq!(by_model.as_bytes(), by_table.as_bytes());

        let bytes = by_table.into_bytes();
        let mut input = BitReader::new(&bytes);
        let mut decoder = ArithmeticDecoder::new(&mut input, 0).unwrap();
        let decoded: Vec<usize> = (0..5)
            .map(|_| decoder.decode(&mut input, &table).unwrap())
            .collect();
        assert_eq!(decoded, [3, 5, 2, 4, 1]);
        assert_eq!(input.position(), by_model.len());
    }

    #[test]
    fn frequency_tables_are_validated() {
        assert!(FrequencyTable::new(&[]).is_err());
        assert!(FrequencyTable::new(&[1, 0]).is_err());
        assert!(FrequencyTable::new(&[MAX_FREQUENCY, 1]).is_err());
        let t = FrequencyTable::new(&[2, 3]).unwrap();
        assert_eq!((t.frequency(0), t.frequency(1), t.total()), (2, 3, 5));
        assert_eq!(
            (t.symbol_above(1), t.symbol_above(2), t.symbol_above(9)),
            (0, 1, 1)
        );
    }
}
