//! Fallible allocation for buffers whose size the user chooses (frames, bake grids, dense
//! copies of VDB data): an allocation the machine cannot satisfy is an error naming what
//! it was for and how much it needed, not an abort ("memory allocation of ... failed").

/// Why a buffer could not be allocated.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("not enough memory for {what}: {bytes} bytes ({gib:.1} GiB) could not be allocated", gib = *bytes as f64 / f64::from(1u32 << 30))]
pub struct AllocError {
    pub what: String,
    pub bytes: u128,
}

/// `len` copies of `value`, or an [`AllocError`] for `what`.
pub fn try_filled<T: Clone>(len: usize, value: T, what: &str) -> Result<Vec<T>, AllocError> {
    let mut v = try_with_capacity(len, what)?;
    v.resize(len, value);
    Ok(v)
}

/// An empty vector with room for `len` elements, or an [`AllocError`] for `what`.
pub fn try_with_capacity<T>(len: usize, what: &str) -> Result<Vec<T>, AllocError> {
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|_| AllocError {
        what: what.to_owned(),
        bytes: len as u128 * std::mem::size_of::<T>() as u128,
    })?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_impossible_buffer_is_an_error_not_an_abort() {
        // 2^60 f32s: more than any address space; try_reserve refuses it.
        let e = try_filled(1usize << 60, 0f32, "a test frame").expect_err("too big");
        assert_eq!(e.bytes, 1u128 << 62);
        assert!(
            e.to_string()
                .starts_with("not enough memory for a test frame: 4611686018427387904 bytes"),
            "{e}"
        );
        assert_eq!(try_filled(3, 7u8, "small").expect("fits"), vec![7, 7, 7]);
    }
}
