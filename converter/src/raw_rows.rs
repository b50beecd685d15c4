//! The row layout of a raw `sensor_msgs/Image` (`step`, row padding, data length), checked the
//! same way for colour ([`crate::images`]) and depth ([`crate::depth`]). Sizes come from the
//! message, so every product is checked (a 4294967295-square image overflows 64 bits).

/// The bytes of pixels in one row (`width × bytes_per_pixel`), once `step` is known to hold a
/// row and `data_len` to hold `height` rows of `step`. `width` and `height` are non-zero (the
/// callers report empty images in their own words). The error says what is wrong.
pub(crate) fn checked_row_bytes(
    width: usize,
    height: usize,
    step: usize,
    bytes_per_pixel: usize,
    data_len: usize,
) -> Result<usize, String> {
    let row = width
        .checked_mul(bytes_per_pixel)
        .ok_or_else(|| "absurd width".to_string())?;
    if step < row {
        return Err(format!(
            "step {step} is smaller than width {width} × {bytes_per_pixel} bytes"
        ));
    }
    let needed = step
        .checked_mul(height - 1)
        .and_then(|b| b.checked_add(row))
        .ok_or_else(|| format!("absurd size (step {step})"))?;
    if data_len < needed {
        return Err(format!(
            "{data_len} data bytes, but {height} rows of step {step} need {needed}"
        ));
    }
    Ok(row)
}

#[cfg(test)]
mod tests {
    use super::checked_row_bytes;

    #[test]
    fn padded_rows_pass_and_short_steps_data_or_overflows_are_named() {
        assert_eq!(checked_row_bytes(4, 2, 16, 3, 28), Ok(12));
        let short_step = checked_row_bytes(4, 2, 8, 3, 100).unwrap_err();
        assert!(
            short_step.contains("step 8 is smaller than width 4 × 3"),
            "{short_step}"
        );
        let short_data = checked_row_bytes(4, 2, 16, 3, 27).unwrap_err();
        assert!(
            short_data.contains("27 data bytes, but 2 rows of step 16 need 28"),
            "{short_data}"
        );
        let huge = checked_row_bytes(usize::MAX, 2, usize::MAX, 1, 0).unwrap_err();
        assert!(huge.contains("absurd size"), "{huge}");
        assert!(checked_row_bytes(usize::MAX, 1, 0, 2, 0).is_err());
    }
}
