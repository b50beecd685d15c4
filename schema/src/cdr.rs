//! OMG CDR (XCDR1) as ROS 2 serializes it: a 4-byte encapsulation header, then fields aligned to
//! their size relative to the end of that header.
//!
//! Reading accepts both byte orders and never allocates more than the input could hold: every
//! length is checked against the bytes that remain before anything is reserved.

use crate::error::{Error, Result};

/// Encapsulation header for little-endian plain CDR (`CDR_LE`), what every ROS 2 RMW writes on x86/ARM.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Encapsulation header for big-endian plain CDR (`CDR_BE`).
pub const CDR_BE_HEADER: [u8; 4] = [0x00, 0x00, 0x00, 0x00];

/// Serializes one message body; created with the header already in place.
#[derive(Debug)]
pub struct CdrWriter {
    buf: Vec<u8>,
    big_endian: bool,
}

impl CdrWriter {
    /// A little-endian writer (the ROS 2 default).
    pub fn new() -> Self {
        Self::with_capacity(64, false)
    }

    /// A writer with room for `capacity` body bytes, in the given byte order.
    pub fn with_capacity(capacity: usize, big_endian: bool) -> Self {
        let mut buf = Vec::with_capacity(capacity + 4);
        buf.extend_from_slice(if big_endian {
            &CDR_BE_HEADER
        } else {
            &CDR_LE_HEADER
        });
        Self { buf, big_endian }
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - 4;
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    fn put<const N: usize>(&mut self, le: [u8; N], be: [u8; N]) {
        self.align(N);
        self.buf
            .extend_from_slice(if self.big_endian { &be } else { &le });
    }

    /// Writes a `uint8`.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    /// Writes a `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes(), v.to_be_bytes());
    }
    /// Writes an `int32`.
    pub fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes(), v.to_be_bytes());
    }
    /// Writes a `float64`.
    pub fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes(), v.to_be_bytes());
    }

    fn len_prefix(&mut self, n: usize) {
        // ROS 2 messages never approach 4 GiB; saturate rather than wrap if one ever did.
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    /// Writes the length of a sequence of structs, before its elements.
    pub fn sequence_len(&mut self, n: usize) {
        self.len_prefix(n);
    }

    /// Writes a `string`: length including the NUL terminator, bytes, NUL.
    pub fn string(&mut self, s: &str) {
        self.len_prefix(s.len() + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    /// Writes a `uint8[]`.
    pub fn bytes(&mut self, b: &[u8]) {
        self.len_prefix(b.len());
        self.buf.extend_from_slice(b);
    }
    /// Writes a `float64[]`.
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.len_prefix(v.len());
        for x in v {
            self.f64(*x);
        }
    }
    /// Writes a `string[]`.
    pub fn string_seq(&mut self, v: &[String]) {
        self.len_prefix(v.len());
        for s in v {
            self.string(s);
        }
    }

    /// The serialized message, header included.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

/// Deserializes one message body from a borrowed buffer.
#[derive(Debug)]
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header and positions the reader at the start of the body.
    pub fn new(data: &'a [u8]) -> Result<Self> {
        let head = data.get(..4).ok_or(Error::Cdr {
            offset: 0,
            reason: format!(
                "{} bytes is too short for the 4-byte encapsulation header",
                data.len()
            ),
        })?;
        let big_endian = match (head[0], head[1]) {
            (0x00, 0x01) => false,
            (0x00, 0x00) => true,
            (a, b) => {
                return Err(Error::Cdr {
                    offset: 0,
                    reason: format!(
                        "encapsulation {a:02x} {b:02x} is not plain CDR (00 00 / 00 01)"
                    ),
                })
            }
        };
        Ok(Self {
            body: &data[4..],
            pos: 0,
            big_endian,
        })
    }

    /// True when the payload is big-endian.
    pub fn is_big_endian(&self) -> bool {
        self.big_endian
    }

    /// Bytes left after the current position.
    pub fn remaining(&self) -> usize {
        self.body.len() - self.pos
    }

    fn err(&self, reason: String) -> Error {
        Error::Cdr {
            offset: self.pos + 4,
            reason,
        }
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(self.err(format!(
                "{what}: needs {n} bytes, {} remain",
                self.remaining()
            )));
        }
        let s = &self.body[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn fixed<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let pad = (N - self.pos % N) % N;
        self.take(pad, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        if self.big_endian {
            out.reverse();
        }
        Ok(out) // now little-endian
    }

    /// Reads a `uint8`.
    pub fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1, "uint8")?[0])
    }
    /// Reads a `uint32`.
    pub fn u32(&mut self) -> Result<u32> {
        self.fixed::<4>("uint32").map(u32::from_le_bytes)
    }
    /// Reads an `int32`.
    pub fn i32(&mut self) -> Result<i32> {
        self.fixed::<4>("int32").map(i32::from_le_bytes)
    }
    /// Reads a `float64`.
    pub fn f64(&mut self) -> Result<f64> {
        self.fixed::<8>("float64").map(f64::from_le_bytes)
    }

    /// Reads the length of a sequence of structs (e.g. `geometry_msgs/TransformStamped[]`),
    /// checking that `count * min_elem_size` bytes can still follow.
    pub fn sequence_len(&mut self, min_elem_size: usize) -> Result<usize> {
        self.seq_len(min_elem_size, "sequence")
    }

    /// Reads a sequence length and checks that `count * min_elem_size` bytes can still follow.
    fn seq_len(&mut self, min_elem_size: usize, what: &str) -> Result<usize> {
        let n = self.u32()? as usize;
        if n.saturating_mul(min_elem_size) > self.remaining() {
            return Err(self.err(format!(
                "{what}: length {n} needs at least {} bytes, {} remain",
                n.saturating_mul(min_elem_size),
                self.remaining()
            )));
        }
        Ok(n)
    }

    /// Reads a `string` (borrowed, without its NUL).
    pub fn str(&mut self) -> Result<&'a str> {
        let n = self.seq_len(1, "string")?;
        let raw = self.take(n, "string")?;
        let raw = match raw.split_last() {
            Some((0, rest)) => rest,
            Some(_) => return Err(self.err("string is not NUL-terminated".into())),
            None => raw, // some writers encode "" as length 0
        };
        std::str::from_utf8(raw).map_err(|e| self.err(format!("string is not UTF-8: {e}")))
    }
    /// Reads a `string` into an owned `String`.
    pub fn string(&mut self) -> Result<String> {
        self.str().map(str::to_owned)
    }
    /// Reads a `uint8[]` without copying it.
    pub fn bytes(&mut self) -> Result<&'a [u8]> {
        let n = self.seq_len(1, "uint8[]")?;
        self.take(n, "uint8[]")
    }
    /// Reads a `float64[]`.
    pub fn f64_seq(&mut self) -> Result<Vec<f64>> {
        let n = self.seq_len(8, "float64[]")?;
        (0..n).map(|_| self.f64()).collect()
    }
    /// Reads a `string[]`.
    pub fn string_seq(&mut self) -> Result<Vec<String>> {
        // Each element is at least a 4-byte length.
        let n = self.seq_len(4, "string[]")?;
        (0..n).map(|_| self.string()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_is_relative_to_the_body() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        let b = w.finish();
        // 4 header + 1 byte + 7 padding + 8 bytes
        assert_eq!(b.len(), 4 + 16);
        let mut r = CdrReader::new(&b).unwrap();
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.f64().unwrap(), 1.5);
    }

    #[test]
    fn both_byte_orders_round_trip() {
        for be in [false, true] {
            let mut w = CdrWriter::with_capacity(0, be);
            w.i32(-5);
            w.string("fr3_joint1");
            w.f64_seq(&[0.25, -1.0]);
            w.string_seq(&["a".into(), String::new()]);
            w.bytes(&[1, 2, 3]);
            let b = w.finish();
            assert_eq!(b[1], u8::from(!be));
            let mut r = CdrReader::new(&b).unwrap();
            assert_eq!(r.is_big_endian(), be);
            assert_eq!(r.i32().unwrap(), -5);
            assert_eq!(r.str().unwrap(), "fr3_joint1");
            assert_eq!(r.f64_seq().unwrap(), vec![0.25, -1.0]);
            assert_eq!(
                r.string_seq().unwrap(),
                vec!["a".to_string(), String::new()]
            );
            assert_eq!(r.bytes().unwrap(), &[1, 2, 3]);
            assert_eq!(r.remaining(), 0);
        }
    }

    #[test]
    fn hostile_lengths_are_errors_not_allocations() {
        for bad_len in [u32::MAX, 1 << 30, 9] {
            let mut b = CDR_LE_HEADER.to_vec();
            b.extend_from_slice(&bad_len.to_le_bytes());
            b.extend_from_slice(&[0u8; 8]);
            for read in [
                |r: &mut CdrReader| r.bytes().map(drop),
                |r: &mut CdrReader| r.str().map(drop),
                |r: &mut CdrReader| r.f64_seq().map(drop),
                |r: &mut CdrReader| r.string_seq().map(drop),
            ] {
                let mut r = CdrReader::new(&b).unwrap();
                let e = read(&mut r).unwrap_err().to_string();
                assert!(e.contains("remain"), "{e}");
            }
        }
    }

    #[test]
    fn bad_headers_and_truncation_are_reported() {
        assert!(CdrReader::new(&[0, 1]).is_err());
        assert!(CdrReader::new(&[0, 7, 0, 0]).is_err());
        let mut r = CdrReader::new(&[0, 1, 0, 0, 1, 2]).unwrap();
        assert!(r.u32().is_err());
        let mut b = CDR_LE_HEADER.to_vec();
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(b"abc");
        assert!(CdrReader::new(&b)
            .unwrap()
            .str()
            .unwrap_err()
            .to_string()
            .contains("NUL"));
    }
}
