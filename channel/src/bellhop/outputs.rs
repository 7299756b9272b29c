//! BELLHOP's outputs: the `.shd` pressure field (Fortran direct-access
//! records of 4-byte words), the `.arr` arrivals file (ASCII for run type
//! `A`, Fortran unformatted records for `a`) and the `.ray` file of a ray
//! or eigenray run (`R`, `E`).

use num_complex::Complex64;

use super::records::Records;
use crate::arrivals::{Arrival, ArrivalField};
use crate::error::ParseError;
use crate::field::TlField;

/// A `.shd` file: the complex pressure for each source depth on the
/// receiver grid.
#[derive(Debug, Clone, PartialEq)]
pub struct ShdFile {
    /// Title (trimmed).
    pub title: String,
    /// Plot type (`rectilin`, `irregular`).
    pub plot_type: String,
    /// Frequency (Hz).
    pub frequency: f64,
    /// Source depths (m).
    pub source_depths: Vec<f64>,
    /// Receiver depths (m).
    pub depths: Vec<f64>,
    /// Receiver ranges (m).
    pub ranges: Vec<f64>,
    /// One field per source depth: `pressure[source][iz * ranges + ir]`.
    pub pressure: Vec<Vec<Complex64>>,
}

impl ShdFile {
    /// The field of source index `is` as a [`TlField`].
    pub fn field(&self, is: usize) -> Option<TlField> {
        Some(TlField {
            source_depth: *self.source_depths.get(is)?,
            depths: self.depths.clone(),
            ranges: self.ranges.clone(),
            pressure: self.pressure.get(is)?.clone(),
        })
    }
}

fn shd_error(name: &str, field: &str, message: impl Into<String>) -> ParseError {
    ParseError {
        file: name.to_string(),
        line: 0,
        field: field.to_string(),
        message: message.into(),
    }
}

struct Words<'a> {
    name: &'a str,
    bytes: &'a [u8],
    recl: usize,
}

impl Words<'_> {
    /// Word `w` (0-based) of record `rec` (0-based).
    fn word(&self, rec: usize, w: usize, field: &str) -> Result<[u8; 4], ParseError> {
        let at = (rec * self.recl + w) * 4;
        self.bytes
            .get(at..at + 4)
            .and_then(|b| b.try_into().ok())
            .ok_or_else(|| {
                shd_error(
                    self.name,
                    field,
                    format!(
                        "the file ends at byte {} (record {})",
                        self.bytes.len(),
                        rec + 1
                    ),
                )
            })
    }

    fn i32(&self, rec: usize, w: usize, field: &str) -> Result<i32, ParseError> {
        Ok(i32::from_le_bytes(self.word(rec, w, field)?))
    }

    fn f32(&self, rec: usize, w: usize, field: &str) -> Result<f32, ParseError> {
        Ok(f32::from_le_bytes(self.word(rec, w, field)?))
    }

    fn count(&self, rec: usize, w: usize, field: &str) -> Result<usize, ParseError> {
        let n = self.i32(rec, w, field)?;
        if n < 0 || n as usize > self.recl.max(1) * 2 + 1_000_000 {
            return Err(shd_error(
                self.name,
                field,
                format!("{n} is not a plausible count"),
            ));
        }
        Ok(n as usize)
    }

    fn text(&self, rec: usize, from: usize, len: usize, field: &str) -> Result<String, ParseError> {
        let at = rec * self.recl * 4 + from;
        let b = self
            .bytes
            .get(at..at + len)
            .ok_or_else(|| shd_error(self.name, field, "the file ends in the header"))?;
        Ok(String::from_utf8_lossy(b).trim().to_string())
    }

    fn floats(&self, rec: usize, n: usize, field: &str) -> Result<Vec<f64>, ParseError> {
        (0..n)
            .map(|i| self.f32(rec, i, field).map(f64::from))
            .collect()
    }
}

/// Reads a `.shd` file's bytes (`name` for errors).
pub fn read_shd(name: &str, bytes: &[u8]) -> Result<ShdFile, ParseError> {
    let first = bytes
        .get(0..4)
        .ok_or_else(|| shd_error(name, "record length", "the file is shorter than 4 bytes"))?;
    let recl = i32::from_le_bytes([first[0], first[1], first[2], first[3]]);
    if !(41..=100_000_000).contains(&recl) {
        return Err(shd_error(
            name,
            "record length",
            format!("{recl} words is not a .shd record length"),
        ));
    }
    let w = Words {
        name,
        bytes,
        recl: recl as usize,
    };
    let title = w.text(0, 4, 80, "title")?;
    let plot_type = w.text(1, 0, 10, "plot type")?;
    let nfreq = w.count(2, 0, "number of frequencies")?;
    let ntheta = w.count(2, 1, "number of bearings")?;
    let nsz = w.count(2, 4, "number of source depths")?;
    let nrz = w.count(2, 5, "number of receiver depths")?;
    let nrr = w.count(2, 6, "number of receiver ranges")?;
    if 2 * nrr > w.recl || nrz > w.recl || nsz > w.recl {
        return Err(shd_error(
            name,
            "sizes",
            "the grid does not fit the record length",
        ));
    }
    let frequency = f64::from(w.f32(2, 7, "frequency")?);
    let source_depths = w.floats(7, nsz, "source depths")?;
    let depths = w.floats(8, nrz, "receiver depths")?;
    let ranges = w.floats(9, nrr, "receiver ranges")?;
    let mut pressure = Vec::with_capacity(nsz);
    let per_source = nrz;
    let _ = (nfreq, ntheta);
    for is in 0..nsz {
        let mut p = Vec::with_capacity(nrz * nrr);
        for iz in 0..nrz {
            let rec = 10 + is * per_source + iz;
            for ir in 0..nrr {
                let re = w.f32(rec, 2 * ir, "pressure")?;
                let im = w.f32(rec, 2 * ir + 1, "pressure")?;
                p.push(Complex64::new(re.into(), im.into()));
            }
        }
        pressure.push(p);
    }
    Ok(ShdFile {
        title,
        plot_type,
        frequency,
        source_depths,
        depths,
        ranges,
        pressure,
    })
}

/// Writes TL fields (one per source depth, on the same grid) as a `.shd`
/// file BELLHOP's plotting tools read.
pub fn write_shd(title: &str, frequency: f64, fields: &[TlField]) -> Vec<u8> {
    let Some(first) = fields.first() else {
        return Vec::new();
    };
    let (nrz, nrr, nsz) = (first.depths.len(), first.ranges.len(), fields.len());
    let recl = 41usize.max(nsz).max(nrz).max(2 * nrr);
    let records = 10 + nsz * nrz;
    let mut out = vec![0u8; records * recl * 4];
    let mut put = |rec: usize, word: usize, bytes: [u8; 4]| {
        let at = (rec * recl + word) * 4;
        out[at..at + 4].copy_from_slice(&bytes);
    };
    put(0, 0, (recl as i32).to_le_bytes());
    let mut t = [b' '; 80];
    for (d, s) in t.iter_mut().zip(title.bytes()) {
        *d = s;
    }
    for (k, chunk) in t.chunks(4).enumerate() {
        put(0, 1 + k, [chunk[0], chunk[1], chunk[2], chunk[3]]);
    }
    let plot = *b"rectilin    ";
    for k in 0..3 {
        put(
            1,
            k,
            [
                plot[4 * k],
                plot[4 * k + 1],
                plot[4 * k + 2],
                plot[4 * k + 3],
            ],
        );
    }
    for (k, v) in [1, 1, 1, 1, nsz, nrz, nrr].iter().enumerate() {
        put(2, k, (*v as i32).to_le_bytes());
    }
    put(2, 7, (frequency as f32).to_le_bytes());
    put(2, 8, 0f32.to_le_bytes());
    let f = frequency.to_le_bytes();
    put(3, 0, [f[0], f[1], f[2], f[3]]);
    put(3, 1, [f[4], f[5], f[6], f[7]]);
    for (rec, values) in [
        (
            7usize,
            fields.iter().map(|f| f.source_depth).collect::<Vec<_>>(),
        ),
        (8, first.depths.clone()),
        (9, first.ranges.clone()),
    ] {
        for (k, v) in values.iter().enumerate() {
            put(rec, k, (*v as f32).to_le_bytes());
        }
    }
    for (is, field) in fields.iter().enumerate() {
        for iz in 0..nrz {
            for ir in 0..nrr {
                let p = field.pressure_at(iz, ir);
                put(10 + is * nrz + iz, 2 * ir, (p.re as f32).to_le_bytes());
                put(10 + is * nrz + iz, 2 * ir + 1, (p.im as f32).to_le_bytes());
            }
        }
    }
    out
}

/// An ASCII `.arr` file: the arrivals for each source depth.
#[derive(Debug, Clone, PartialEq)]
pub struct ArrFile {
    /// Frequency (Hz).
    pub frequency: f64,
    /// One field per source depth.
    pub fields: Vec<ArrivalField>,
}

/// An arrival from the eight values of a `.arr` line (`value(k)`, k from
/// 0), rounded to single precision as BELLHOP writes them: amplitude,
/// phase (degrees), delay and its imaginary part (s), source and receiver
/// angles (degrees), surface and bottom bounces.
fn arrival_of(value: impl Fn(usize) -> f64) -> Arrival {
    let single = |k: usize| f64::from(value(k) as f32);
    Arrival {
        amplitude: single(0),
        phase: single(1).to_radians(),
        delay: single(2),
        delay_imag: single(3),
        source_angle: single(4),
        receiver_angle: single(5),
        top_bounces: value(6).max(0.0) as u32,
        bottom_bounces: value(7).max(0.0) as u32,
    }
}

/// One source's arrivals on the receiver grid of a `.arr` file.
fn field_of(sd: f64, depths: &[f64], ranges: &[f64], arrivals: Vec<Vec<Arrival>>) -> ArrivalField {
    ArrivalField {
        source_depth: sd,
        depths: depths.to_vec(),
        ranges: ranges.to_vec(),
        arrivals,
    }
}

/// Reads an ASCII `.arr` file (`name` for errors).
pub fn read_arr(name: &str, text: &str) -> Result<ArrFile, ParseError> {
    let mut r = Records::new(name, text);
    let kind = r.read_one("dimension")?;
    if kind.text.trim() != "2D" {
        return Err(r.error(
            kind.line,
            "dimension",
            format!("'{}' files are not read (2D only)", kind.text),
        ));
    }
    let frequency = r.read_number("frequency")?;
    let mut axes = Vec::new();
    for field in ["source depths", "receiver depths", "receiver ranges"] {
        axes.push(r.read_counted(field)?);
    }
    let (sources, depths, ranges) = (axes[0].clone(), axes[1].clone(), axes[2].clone());
    let mut fields = Vec::with_capacity(sources.len());
    for &sd in &sources {
        r.read_count("maximum number of arrivals", 0, 100_000_000)?;
        let mut arrivals = Vec::with_capacity(depths.len() * ranges.len());
        for _ in 0..depths.len() * ranges.len() {
            let n = r.read_count("number of arrivals", 0, 100_000_000)?;
            let mut list = Vec::with_capacity(n);
            for k in 0..n {
                let field = format!("arrival {}", k + 1);
                let line = r.line();
                let v = r.read_numbers(8, &field)?;
                if v.len() < 8 {
                    return Err(r.error(line, &field, "8 values expected"));
                }
                list.push(arrival_of(|k| v[k].0));
            }
            arrivals.push(list);
        }
        fields.push(field_of(sd, &depths, &ranges, arrivals));
    }
    Ok(ArrFile { frequency, fields })
}

/// Writes arrival fields (one per source depth, same grid) as an ASCII
/// `.arr` file, values in single precision as BELLHOP writes them
/// (amplitude, phase in degrees, delay and its imaginary part in s, source
/// and receiver angles in degrees, surface and bottom bounces).
pub fn write_arr(frequency: f64, fields: &[ArrivalField]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let Some(first) = fields.first() else {
        return s;
    };
    let list = |v: &[f64]| {
        let mut l = format!("{}", v.len());
        for x in v {
            let _ = write!(l, " {}", *x as f32);
        }
        l
    };
    let sd: Vec<f64> = fields.iter().map(|f| f.source_depth).collect();
    let _ = writeln!(
        s,
        "'2D'\n{frequency}\n{}\n{}\n{}",
        list(&sd),
        list(&first.depths),
        list(&first.ranges)
    );
    for f in fields {
        let max = f.arrivals.iter().map(Vec::len).max().unwrap_or(0);
        let _ = writeln!(s, "{max}");
        for a in &f.arrivals {
            let _ = writeln!(s, "{}", a.len());
            for x in a {
                let _ = writeln!(
                    s,
                    "{:e} {} {:e} {:e} {} {} {} {}",
                    x.amplitude as f32,
                    x.phase.to_degrees() as f32,
                    x.delay as f32,
                    x.delay_imag as f32,
                    x.source_angle as f32,
                    x.receiver_angle as f32,
                    x.top_bounces,
                    x.bottom_bounces
                );
            }
        }
    }
    s
}

/// Writes arrival fields (one per source depth, same grid) as the binary
/// `.arr` file of run type `a`: Fortran unformatted sequential records
/// (each framed by its length in bytes, little-endian) holding `'2D'`,
/// the frequency, the source depths, receiver depths and ranges (count
/// then single-precision values), then per source the most arrivals at a
/// receiver and per receiver its count and one record per arrival:
/// amplitude, phase (degrees), delay and its imaginary part (s), source
/// and receiver angles (degrees), surface and bottom bounces, all single
/// precision.
pub fn write_arr_binary(frequency: f64, fields: &[ArrivalField]) -> Vec<u8> {
    let mut out = Vec::new();
    let Some(first) = fields.first() else {
        return out;
    };
    let mut record = |words: &[[u8; 4]]| {
        let len = (4 * words.len()) as u32;
        out.extend_from_slice(&len.to_le_bytes());
        for w in words {
            out.extend_from_slice(w);
        }
        out.extend_from_slice(&len.to_le_bytes());
    };
    let single = |x: f64| (x as f32).to_le_bytes();
    let counted = |v: &[f64]| -> Vec<[u8; 4]> {
        std::iter::once((v.len() as i32).to_le_bytes())
            .chain(v.iter().map(|x| single(*x)))
            .collect()
    };
    record(&[*b"'2D'"]);
    record(&[single(frequency)]);
    let sd: Vec<f64> = fields.iter().map(|f| f.source_depth).collect();
    record(&counted(&sd));
    record(&counted(&first.depths));
    record(&counted(&first.ranges));
    for f in fields {
        let max = f.arrivals.iter().map(Vec::len).max().unwrap_or(0);
        record(&[(max as i32).to_le_bytes()]);
        for list in &f.arrivals {
            record(&[(list.len() as i32).to_le_bytes()]);
            for a in list {
                record(&[
                    single(a.amplitude),
                    single(a.phase.to_degrees()),
                    single(a.delay),
                    single(a.delay_imag),
                    single(a.source_angle),
                    single(a.receiver_angle),
                    single(f64::from(a.top_bounces)),
                    single(f64::from(a.bottom_bounces)),
                ]);
            }
        }
    }
    out
}

/// Fortran unformatted sequential records, read without panics.
struct Unformatted<'a> {
    name: &'a str,
    bytes: &'a [u8],
    at: usize,
    index: usize,
}

impl<'a> Unformatted<'a> {
    /// The next record's bytes (its length checked at both ends).
    fn record(&mut self, field: &str) -> Result<&'a [u8], ParseError> {
        self.index += 1;
        let fail = |m: String| shd_error(self.name, field, format!("record {}: {m}", self.index));
        let head = self
            .bytes
            .get(self.at..self.at + 4)
            .ok_or_else(|| fail(format!("the file ends at byte {}", self.bytes.len())))?;
        let len = u32::from_le_bytes([head[0], head[1], head[2], head[3]]) as usize;
        let body = self
            .bytes
            .get(self.at + 4..self.at + 4 + len)
            .ok_or_else(|| fail(format!("{len} bytes announced past the end of the file")))?;
        let tail = self
            .bytes
            .get(self.at + 4 + len..self.at + 8 + len)
            .ok_or_else(|| fail("the file ends before the record's end mark".into()))?;
        if u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]) as usize != len {
            return Err(fail("its end mark is not its length".into()));
        }
        self.at += 8 + len;
        Ok(body)
    }

    /// The next record as 4-byte words (at least `min`).
    fn words(&mut self, min: usize, field: &str) -> Result<Vec<[u8; 4]>, ParseError> {
        let body = self.record(field)?;
        if body.len() % 4 != 0 || body.len() < 4 * min {
            return Err(shd_error(
                self.name,
                field,
                format!(
                    "record {}: {} bytes, not {min} words",
                    self.index,
                    body.len()
                ),
            ));
        }
        Ok(body.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect())
    }

    /// A count record (`max` at most).
    fn count(&mut self, max: usize, field: &str) -> Result<usize, ParseError> {
        let w = self.words(1, field)?;
        let n = i32::from_le_bytes(w[0]);
        if n < 0 || n as usize > max {
            return Err(shd_error(
                self.name,
                field,
                format!("{n} is not a plausible count"),
            ));
        }
        Ok(n as usize)
    }

    /// A count followed by that many single-precision values.
    fn counted(&mut self, field: &str) -> Result<Vec<f64>, ParseError> {
        let w = self.words(1, field)?;
        let n = i32::from_le_bytes(w[0]);
        if n < 0 || n as usize != w.len() - 1 {
            return Err(shd_error(
                self.name,
                field,
                format!("{n} values announced, {} given", w.len() - 1),
            ));
        }
        Ok(w[1..]
            .iter()
            .map(|b| f64::from(f32::from_le_bytes(*b)))
            .collect())
    }
}

/// Reads a binary `.arr` file (run type `a`; `name` for errors).
pub fn read_arr_binary(name: &str, bytes: &[u8]) -> Result<ArrFile, ParseError> {
    let mut r = Unformatted {
        name,
        bytes,
        at: 0,
        index: 0,
    };
    let kind = r.record("dimension")?;
    if kind != b"'2D'" {
        return Err(shd_error(
            name,
            "dimension",
            format!(
                "'{}' files are not read (2D only)",
                String::from_utf8_lossy(kind)
            ),
        ));
    }
    let frequency = f64::from(f32::from_le_bytes(r.words(1, "frequency")?[0]));
    let sources = r.counted("source depths")?;
    let depths = r.counted("receiver depths")?;
    let ranges = r.counted("receiver ranges")?;
    let limit = bytes.len() / 40;
    let mut fields = Vec::with_capacity(sources.len());
    for &sd in &sources {
        r.count(limit, "maximum number of arrivals")?;
        let mut arrivals = Vec::with_capacity((depths.len() * ranges.len()).min(limit));
        for _ in 0..depths.len() * ranges.len() {
            let n = r.count(limit, "number of arrivals")?;
            let mut list = Vec::with_capacity(n);
            for k in 0..n {
                let w = r.words(8, &format!("arrival {}", k + 1))?;
                list.push(arrival_of(|i| f64::from(f32::from_le_bytes(w[i]))));
            }
            arrivals.push(list);
        }
        fields.push(field_of(sd, &depths, &ranges, arrivals));
    }
    Ok(ArrFile { frequency, fields })
}

/// The rays of one source, for a `.ray` file.
#[derive(Debug, Clone, Copy)]
pub struct RaySet<'a> {
    /// Source depth (m).
    pub source_depth: f64,
    /// Its rays (or eigenrays), in launch order.
    pub rays: &'a [crate::RayPath],
}

/// Writes rays as BELLHOP's ASCII `.ray` file, which `plotray` draws: the
/// title, frequency, source counts (1, 1, sources), beams per source and
/// 1, the surface and bottom depths (m), `'rz'`, then per ray its launch
/// angle (degrees), its point count with its surface and bottom bounces,
/// and its points `range depth` (m), sources one after the other.
pub fn write_ray(
    title: &str,
    frequency: f64,
    beams: usize,
    (top, bottom): (f64, f64),
    sources: &[RaySet<'_>],
) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "'{}'\n{frequency}\n1 1 {}\n{beams} 1\n{top}\n{bottom}\n'rz'",
        title.replace('\'', "''"),
        sources.len()
    );
    for set in sources {
        for ray in set.rays {
            let _ = writeln!(
                s,
                "{}\n{} {} {}",
                ray.angle,
                ray.points.len(),
                ray.top_bounces,
                ray.bottom_bounces
            );
            for (r, z) in &ray.points {
                let _ = writeln!(s, "{r} {z}");
            }
        }
    }
    s
}
