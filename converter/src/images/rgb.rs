//! The decoded colour image every camera frame becomes before it is resized and encoded.

/// Tightly packed RGB8 pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Rgb {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height × 3` bytes.
    pub data: Vec<u8>,
}
