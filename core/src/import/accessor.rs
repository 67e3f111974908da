//! Bounds-checked accessor decoding: every component type, normalisation,
//! byte strides, matrix column padding and sparse substitution.
//!
//! The gltf crate's reader trusts offsets and strides and can panic on a
//! file that lies about them; this one checks every range against the bytes
//! that are really there and reports the accessor that is wrong.

use gltf::json::{
    self,
    accessor::{ComponentType, Type},
    validation::Checked,
};

use super::{ImportError, document::Document, limits::Limits};

/// Decoded accessor data, flattened: `values.len() == count * width`.
#[derive(Debug)]
pub(crate) struct Decoded<T> {
    pub(crate) width: usize,
    pub(crate) values: Vec<T>,
}

impl Decoded<f32> {
    pub(crate) fn vec3(&self) -> Vec<glam::Vec3> {
        self.values
            .chunks_exact(3)
            .map(glam::Vec3::from_slice)
            .collect()
    }
}

pub(crate) struct Accessors<'a> {
    pub(crate) root: &'a json::Root,
    pub(crate) buffers: &'a [Vec<u8>],
    /// Accessors read so far whose declared `min` or `max` is not their
    /// data's (ACCESSOR_MIN_MISMATCH / ACCESSOR_MAX_MISMATCH).
    mismatched: std::cell::RefCell<std::collections::BTreeSet<usize>>,
    /// Numbers decoded so far from accessors without a bufferView (the
    /// document's count, over every pass that reads it), and their limit.
    zero_filled: &'a std::cell::Cell<u64>,
    max_zero_filled: u64,
}

impl<'a> Accessors<'a> {
    pub(crate) fn new(doc: &'a Document, limits: &Limits) -> Self {
        Self {
            root: &doc.root,
            buffers: &doc.buffers,
            mismatched: Default::default(),
            zero_filled: &doc.zero_filled,
            max_zero_filled: limits.max_zero_filled,
        }
    }

    /// A warning naming the accessors whose declared bounds their data
    /// does not have: aobake computes its own bounds, so it only says so.
    pub(crate) fn bounds_warning(&self) -> Option<String> {
        let mismatched = self.mismatched.borrow();
        let first: Vec<String> = mismatched.iter().take(8).map(usize::to_string).collect();
        (!mismatched.is_empty()).then(|| {
            format!(
                "{} accessors declare a min or max their data does not have (accessors {}{}); aobake uses the data",
                mismatched.len(),
                first.join(", "),
                if mismatched.len() > first.len() { ", …" } else { "" }
            )
        })
    }
}

/// Whether an accessor's declared `min`/`max` differ from its decoded
/// values (compared as f32, as they are stored; normalised integers are
/// declared unscaled and are not compared).
fn bounds_differ(accessor: &json::Accessor, values: &[f64], width: usize) -> bool {
    let declared = |v: &Option<json::Value>| -> Option<Vec<f32>> {
        v.as_ref()?
            .as_array()?
            .iter()
            .map(|x| x.as_f64().map(|x| x as f32))
            .collect()
    };
    let (min, max) = (declared(&accessor.min), declared(&accessor.max));
    if (min.is_none() && max.is_none()) || values.is_empty() {
        return false;
    }
    let mut lo = vec![f32::INFINITY; width];
    let mut hi = vec![f32::NEG_INFINITY; width];
    for element in values.chunks_exact(width) {
        for (c, &v) in element.iter().enumerate() {
            lo[c] = lo[c].min(v as f32);
            hi[c] = hi[c].max(v as f32);
        }
    }
    min.is_some_and(|m| m != lo) || max.is_some_and(|m| m != hi)
}

fn width_of(ty: Type) -> usize {
    match ty {
        Type::Scalar => 1,
        Type::Vec2 => 2,
        Type::Vec3 => 3,
        Type::Vec4 | Type::Mat2 => 4,
        Type::Mat3 => 9,
        Type::Mat4 => 16,
    }
}

/// Byte offset of each component within one element, with the column
/// padding glTF requires for 1- and 2-byte matrices (spec §3.6.2.4), and
/// the element's size including that padding.
fn layout(ty: Type, size: usize) -> (Vec<usize>, usize) {
    let (columns, rows) = match ty {
        Type::Mat2 => (2, 2),
        Type::Mat3 => (3, 3),
        Type::Mat4 => (4, 4),
        other => (1, width_of(other)),
    };
    let column_stride = if columns > 1 {
        (rows * size).next_multiple_of(4)
    } else {
        rows * size
    };
    let offsets = (0..columns)
        .flat_map(|c| (0..rows).map(move |r| c * column_stride + r * size))
        .collect();
    (offsets, columns * column_stride)
}

#[derive(Clone, Copy)]
enum Kind {
    Float,
    Int { normalized: bool },
}

fn decode(bytes: &[u8], ct: ComponentType, kind: Kind) -> f64 {
    let v = match ct {
        ComponentType::I8 => f64::from(bytes[0] as i8),
        ComponentType::U8 => f64::from(bytes[0]),
        ComponentType::I16 => f64::from(i16::from_le_bytes([bytes[0], bytes[1]])),
        ComponentType::U16 => f64::from(u16::from_le_bytes([bytes[0], bytes[1]])),
        ComponentType::U32 => {
            f64::from(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
        }
        ComponentType::F32 => {
            f64::from(f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
        }
    };
    match (kind, ct) {
        (Kind::Int { normalized: true }, ComponentType::I8) => (v / 127.0).max(-1.0),
        (Kind::Int { normalized: true }, ComponentType::U8) => v / 255.0,
        (Kind::Int { normalized: true }, ComponentType::I16) => (v / 32767.0).max(-1.0),
        (Kind::Int { normalized: true }, ComponentType::U16) => v / 65535.0,
        _ => v,
    }
}

/// A checked view of `len` bytes of a buffer view.
fn view_bytes<'b>(
    acc: &Accessors<'b>,
    view_index: usize,
    path: &str,
) -> Result<(&'b [u8], Option<usize>), ImportError> {
    let view = acc.root.buffer_views.get(view_index).ok_or_else(|| {
        ImportError::invalid(path, format!("bufferView {view_index} does not exist"))
    })?;
    let vpath = format!("bufferViews[{view_index}]");
    let buffer = acc.buffers.get(view.buffer.value()).ok_or_else(|| {
        ImportError::invalid(
            &vpath,
            format!("buffer {} does not exist", view.buffer.value()),
        )
    })?;
    let offset = view.byte_offset.map_or(0, |o| o.0);
    let len = view.byte_length.0;
    let end = offset
        .checked_add(len)
        .filter(|&e| e <= buffer.len() as u64)
        .ok_or_else(|| {
            ImportError::invalid(
                &vpath,
                format!(
                    "bytes {offset}..{} lie past the end of buffer {} ({} bytes)",
                    offset.saturating_add(len),
                    view.buffer.value(),
                    buffer.len()
                ),
            )
        })?;
    Ok((
        &buffer[offset as usize..end as usize],
        view.byte_stride.map(|s| s.0),
    ))
}

impl Accessors<'_> {
    fn accessor(&self, index: usize) -> Result<&json::Accessor, ImportError> {
        self.root
            .accessors
            .get(index)
            .ok_or_else(|| ImportError::invalid(format!("accessors[{index}]"), "does not exist"))
    }

    /// The element count an accessor declares, for limit checks before
    /// decoding.
    pub(crate) fn count(&self, index: usize) -> Result<u64, ImportError> {
        Ok(self.accessor(index)?.count.0)
    }

    /// Decodes an accessor to floats (normalised integers scaled to [0,1] or
    /// [-1,1]); every value must be finite. `max_count` bounds the element
    /// count before allocation.
    pub(crate) fn floats(&self, index: usize, max_count: u64) -> Result<Decoded<f32>, ImportError> {
        let decoded = self.read(index, max_count, None)?;
        let width = decoded.width;
        let mut values = Vec::with_capacity(decoded.values.len());
        for (i, v) in decoded.values.into_iter().enumerate() {
            if !v.is_finite() {
                return Err(ImportError::invalid(
                    format!("accessors[{index}]"),
                    format!(
                        "element {} component {} is {v}, not a finite number",
                        i / width,
                        i % width
                    ),
                ));
            }
            values.push(v as f32);
        }
        Ok(Decoded { width, values })
    }

    /// Decodes an accessor of unsigned integers (indices, joint indices).
    pub(crate) fn uints(&self, index: usize, max_count: u64) -> Result<Decoded<u32>, ImportError> {
        let accessor = self.accessor(index)?;
        match accessor.component_type {
            Checked::Valid(json::accessor::GenericComponentType(
                ComponentType::U8 | ComponentType::U16 | ComponentType::U32,
            )) => {}
            _ => {
                return Err(ImportError::invalid(
                    format!("accessors[{index}]"),
                    "must have an unsigned integer component type here",
                ));
            }
        }
        let decoded = self.read(index, max_count, Some(Kind::Int { normalized: false }))?;
        Ok(Decoded {
            width: decoded.width,
            values: decoded.values.into_iter().map(|v| v as u32).collect(),
        })
    }

    fn read(
        &self,
        index: usize,
        max_count: u64,
        kind: Option<Kind>,
    ) -> Result<Decoded<f64>, ImportError> {
        let path = format!("accessors[{index}]");
        let accessor = self.accessor(index)?;
        let (Checked::Valid(ty), Checked::Valid(ct)) = (accessor.type_, accessor.component_type)
        else {
            return Err(ImportError::invalid(&path, "unknown type or componentType"));
        };
        let ct = ct.0;
        let kind = kind.unwrap_or(match ct {
            ComponentType::F32 => Kind::Float,
            _ => Kind::Int {
                normalized: accessor.normalized,
            },
        });
        let count = accessor.count.0;
        if count > max_count {
            return Err(ImportError::limit_at(
                format!("{path}.count"),
                format!("{path}.count"),
                count,
                max_count,
            ));
        }
        let count = count as usize;
        let width = width_of(ty);
        let size = ct.size();
        let (offsets, element_size) = layout(ty, size);
        // Check the data's extent before allocating for it.
        let mut source = None;
        if let Some(view_index) = accessor.buffer_view {
            let (bytes, stride) = view_bytes(self, view_index.value(), &path)?;
            let stride = stride.unwrap_or(element_size);
            if stride < element_size {
                return Err(ImportError::invalid(
                    &path,
                    format!(
                        "byteStride {stride} is smaller than one element ({element_size} bytes)"
                    ),
                ));
            }
            let start = accessor.byte_offset.map_or(0, |o| o.0);
            if count > 0 {
                let needed = (count as u64 - 1)
                    .checked_mul(stride as u64)
                    .and_then(|v| v.checked_add(start))
                    .and_then(|v| v.checked_add(element_size as u64));
                if needed.is_none_or(|n| n > bytes.len() as u64) {
                    return Err(ImportError::invalid(
                        &path,
                        format!(
                            "{count} elements of {element_size} bytes (stride {stride}) from byte {start} \
                             do not fit in bufferView {} ({} bytes)",
                            view_index.value(),
                            bytes.len()
                        ),
                    ));
                }
            }
            source = Some((bytes, stride, start as usize));
        } else {
            // Zeros (and what a sparse part puts over them): the file need
            // not carry them, so they are held to a budget of their own
            // rather than to the upload's size.
            let numbers = self
                .zero_filled
                .get()
                .saturating_add((count as u64).saturating_mul(width as u64));
            if numbers > self.max_zero_filled {
                return Err(ImportError::limit_at(
                    &path,
                    format!(
                        "{path}: numbers decoded from accessors without a bufferView (zeros the file does not carry)"
                    ),
                    numbers,
                    self.max_zero_filled,
                ));
            }
            self.zero_filled.set(numbers);
        }
        let mut values = vec![0.0f64; count * width];
        if let Some((bytes, stride, start)) = source {
            for (i, element) in values.chunks_exact_mut(width).enumerate() {
                let base = start + i * stride;
                for (value, offset) in element.iter_mut().zip(&offsets) {
                    *value = decode(&bytes[base + offset..], ct, kind);
                }
            }
        }

        if let Some(sparse) = &accessor.sparse {
            self.apply_sparse(&path, sparse, ty, ct, kind, &mut values, count, width)?;
        }
        if !matches!(kind, Kind::Int { normalized: true })
            && bounds_differ(accessor, &values, width)
        {
            self.mismatched.borrow_mut().insert(index);
        }
        Ok(Decoded { width, values })
    }

    #[allow(clippy::too_many_arguments)]
    fn apply_sparse(
        &self,
        path: &str,
        sparse: &json::accessor::sparse::Sparse,
        ty: Type,
        ct: ComponentType,
        kind: Kind,
        values: &mut [f64],
        count: usize,
        width: usize,
    ) -> Result<(), ImportError> {
        let spath = format!("{path}.sparse");
        let n = sparse.count.0;
        if n > count as u64 {
            return Err(ImportError::invalid(
                &spath,
                format!("count {n} is larger than the accessor's count {count}"),
            ));
        }
        let n = n as usize;
        let Checked::Valid(ict) = sparse.indices.component_type else {
            return Err(ImportError::invalid(
                &spath,
                "unknown indices componentType",
            ));
        };
        let ict = ict.0;
        if !matches!(
            ict,
            ComponentType::U8 | ComponentType::U16 | ComponentType::U32
        ) {
            return Err(ImportError::invalid(
                &spath,
                "indices must be unsigned integers",
            ));
        }
        let (ibytes, _) = view_bytes(self, sparse.indices.buffer_view.value(), &spath)?;
        let istart = sparse.indices.byte_offset.0 as usize;
        let isize = ict.size();
        if istart
            .checked_add(n * isize)
            .is_none_or(|e| e > ibytes.len())
        {
            return Err(ImportError::invalid(
                format!("{spath}.indices"),
                format!("{n} indices do not fit in their bufferView"),
            ));
        }
        let vsize = ct.size();
        let (offsets, element_size) = layout(ty, vsize);
        let (vbytes, _) = view_bytes(self, sparse.values.buffer_view.value(), &spath)?;
        let vstart = sparse.values.byte_offset.0 as usize;
        if vstart
            .checked_add(n * element_size)
            .is_none_or(|e| e > vbytes.len())
        {
            return Err(ImportError::invalid(
                format!("{spath}.values"),
                format!("{n} values do not fit in their bufferView"),
            ));
        }
        let mut previous: Option<usize> = None;
        for k in 0..n {
            let target = decode(
                &ibytes[istart + k * isize..],
                ict,
                Kind::Int { normalized: false },
            ) as usize;
            if target >= count {
                return Err(ImportError::invalid(
                    format!("{spath}.indices"),
                    format!("index {k} is {target}, past the accessor's {count} elements"),
                ));
            }
            if let Some(p) = previous.filter(|&p| target <= p) {
                return Err(ImportError::invalid(
                    format!("{spath}.indices"),
                    format!("index {k} is {target}, after {p}: sparse indices strictly increase"),
                ));
            }
            previous = Some(target);
            let base = vstart + k * element_size;
            for (c, offset) in offsets.iter().enumerate() {
                values[target * width + c] = decode(&vbytes[base + offset..], ct, kind);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_columns_are_padded_for_small_components() {
        assert_eq!(layout(Type::Mat2, 1), (vec![0, 1, 4, 5], 8));
        assert_eq!(layout(Type::Mat3, 1).1, 12);
        assert_eq!(
            layout(Type::Mat3, 2),
            (vec![0, 2, 4, 8, 10, 12, 16, 18, 20], 24)
        );
        assert_eq!(layout(Type::Mat4, 4).0[15], 60);
        assert_eq!(layout(Type::Mat4, 4).1, 64);
        assert_eq!(layout(Type::Vec3, 2), (vec![0, 2, 4], 6));
    }

    #[test]
    fn normalized_integers_map_to_unit_range() {
        let k = Kind::Int { normalized: true };
        assert_eq!(decode(&[255], ComponentType::U8, k), 1.0);
        assert_eq!(decode(&[0x80], ComponentType::I8, k), -1.0);
        assert_eq!(decode(&[0xff, 0xff], ComponentType::U16, k), 1.0);
        assert_eq!(
            decode(
                &[0xff, 0xff],
                ComponentType::U16,
                Kind::Int { normalized: false }
            ),
            65535.0
        );
    }
}
