//! Reading single-file NIfTI-1 volumes (`.nii`, or gzip-compressed `.nii.gz`): the header's
//! dimensions, data type, intensity scaling and voxel-to-world affine, and the voxel values.
//!
//! The affine follows the NIfTI-1 standard as nibabel reads it: the sform when `sform_code > 0`,
//! else the qform (quaternion, offsets, pixdim and qfac) when `qform_code > 0`, else a diagonal of
//! the voxel sizes. World coordinates are NIfTI's RAS+ (x to the right, y anterior, z superior),
//! in mm (`xyzt_units` in metres or micrometres are converted). Values are `scl_slope·v +
//! scl_inter` when the slope is non-zero, as the standard says.

use crate::error::{HasError, Result};
use std::io::Read;
use std::path::Path;

/// Bytes in a NIfTI-1 header.
const HEADER_BYTES: usize = 348;

/// A 3-D NIfTI volume.
#[derive(Debug, Clone, PartialEq)]
pub struct Volume {
    /// Shape `(nk, nj, ni)`: slowest axis first, so `values[(k·nj + j)·ni + i]` is voxel (i, j, k).
    pub shape: [usize; 3],
    /// Voxel values after the header's intensity scaling, row-major `(k, j, i)`.
    pub values: Vec<f32>,
    /// Voxel indices (i, j, k, 1) to world RAS+ mm: rows x, y, z of the 4x4 affine.
    pub affine: [[f64; 4]; 3],
}

/// Reads a NIfTI-1 file; errors name the file and say what is wrong in one line.
pub fn read(path: &Path) -> Result<Volume> {
    let p = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| HasError::reading(&p, &e))?;
    let bad = |reason: String| HasError::BadFile { path: p.clone(), reason };
    let data = decompress(&bytes).map_err(bad)?;
    let header = Header::parse(&data).map_err(bad)?;
    let n = header.voxels();
    crate::memory::check(|| format!("the CT volume {p} ({n} voxels)"), 4 * n as u64, "crop the volume to the head and the beam path")?;
    decode(&data, &header).map_err(bad)
}

/// Parses the bytes of a `.nii` or `.nii.gz` file.
pub fn parse(bytes: &[u8]) -> std::result::Result<Volume, String> {
    let data = decompress(bytes)?;
    let header = Header::parse(&data)?;
    decode(&data, &header)
}

/// The bytes, gunzipped if they are gzip (by their magic number, whatever the file's name).
fn decompress(bytes: &[u8]) -> std::result::Result<std::borrow::Cow<'_, [u8]>, String> {
    if !bytes.starts_with(&[0x1f, 0x8b]) {
        return Ok(std::borrow::Cow::Borrowed(bytes));
    }
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes).read_to_end(&mut out).map_err(|e| format!("not a readable gzip file ({e})"))?;
    Ok(std::borrow::Cow::Owned(out))
}

/// The voxel values after the header's scaling.
fn decode(data: &[u8], h: &Header) -> std::result::Result<Volume, String> {
    let start = h.vox_offset;
    let n = h.voxels();
    let size = h.bytes_per_voxel;
    let end = n.checked_mul(size).and_then(|b| b.checked_add(start)).ok_or("dimensions overflow")?;
    if data.len() < end {
        return Err(format!("truncated: the header promises {n} voxels ({end} bytes), the file holds {} bytes", data.len()));
    }
    let mut values: Vec<f32> = data[start..end].chunks_exact(size).map(|b| h.decode(b)).collect();
    if h.slope != 0.0 && h.slope.is_finite() && h.intercept.is_finite() && (h.slope, h.intercept) != (1.0, 0.0) {
        values.iter_mut().for_each(|v| *v = (h.slope as f64 * *v as f64 + h.intercept as f64) as f32);
    }
    Ok(Volume { shape: [h.shape[2], h.shape[1], h.shape[0]], values, affine: h.affine })
}

/// The parts of the header this reader uses.
struct Header {
    big_endian: bool,
    /// (ni, nj, nk).
    shape: [usize; 3],
    datatype: i16,
    bytes_per_voxel: usize,
    vox_offset: usize,
    slope: f32,
    intercept: f32,
    affine: [[f64; 4]; 3],
}

impl Header {
    /// Voxels in the volume.
    fn voxels(&self) -> usize {
        self.shape.iter().product()
    }

    fn parse(d: &[u8]) -> std::result::Result<Header, String> {
        if d.len() < HEADER_BYTES {
            return Err(format!("not a NIfTI file: {} bytes, a header needs {HEADER_BYTES}", d.len()));
        }
        let size_le = i32::from_le_bytes([d[0], d[1], d[2], d[3]]);
        let size_be = i32::from_be_bytes([d[0], d[1], d[2], d[3]]);
        let big_endian = match (size_le, size_be) {
            (348, _) => false,
            (_, 348) => true,
            (540, _) | (_, 540) => return Err("NIfTI-2 is not supported: save the volume as NIfTI-1 (e.g. nibabel.Nifti1Image)".into()),
            _ => return Err("not a NIfTI-1 file (sizeof_hdr is not 348)".into()),
        };
        if &d[344..347] != b"n+1" {
            return Err("not a single-file NIfTI-1 (.nii) volume: magic is not 'n+1'".into());
        }
        let r = Reader { d, big_endian };
        let dim: Vec<i16> = (0..8).map(|i| r.i16(40 + 2 * i)).collect();
        let rank = dim[0];
        if !(1..=7).contains(&rank) {
            return Err(format!("dim[0] = {rank}: not a valid number of dimensions"));
        }
        let extent = |a: usize| if a as i16 <= rank { dim[a] } else { 1 };
        if (4..=7).any(|a| extent(a) != 1) {
            return Err(format!("must be one 3-D volume, got dimensions {:?}", &dim[1..=rank as usize]));
        }
        let mut shape = [0usize; 3];
        for (a, s) in shape.iter_mut().enumerate() {
            let e = extent(a + 1);
            if e < 1 {
                return Err(format!("dim[{}] = {e}: every extent must be >= 1", a + 1));
            }
            *s = e as usize;
        }
        let datatype = r.i16(70);
        let bytes_per_voxel = match datatype {
            2 | 256 => 1,
            4 | 512 => 2,
            8 | 16 | 768 => 4,
            64 => 8,
            t => return Err(format!("data type code {t} is not supported (use int8/16/32, uint8/16/32, float32 or float64)")),
        };
        let vox_offset = r.f32(108);
        if !(vox_offset.is_finite() && vox_offset >= HEADER_BYTES as f32) {
            return Err(format!("vox_offset {vox_offset} lies inside the header"));
        }
        let pixdim: Vec<f64> = (0..8).map(|i| r.f32(76 + 4 * i) as f64).collect();
        let unit = match r.d[123] & 0x07 {
            1 => 1e3,
            3 => 1e-3,
            _ => 1.0, // mm, or unknown (taken as mm, as nibabel does)
        };
        let mut affine = if r.i16(254) > 0 {
            let row = |o: usize| [r.f32(o) as f64, r.f32(o + 4) as f64, r.f32(o + 8) as f64, r.f32(o + 12) as f64];
            [row(280), row(296), row(312)]
        } else if r.i16(252) > 0 {
            qform(&r, &pixdim)
        } else {
            [[pixdim[1], 0.0, 0.0, 0.0], [0.0, pixdim[2], 0.0, 0.0], [0.0, 0.0, pixdim[3], 0.0]]
        };
        affine.iter_mut().flatten().for_each(|v| *v *= unit);
        if affine.iter().flatten().any(|v| !v.is_finite()) {
            return Err("the voxel-to-world affine is not finite".into());
        }
        Ok(Header {
            big_endian,
            shape,
            datatype,
            bytes_per_voxel,
            vox_offset: vox_offset as usize,
            slope: r.f32(112),
            intercept: r.f32(116),
            affine,
        })
    }

    /// One voxel's stored value.
    fn decode(&self, b: &[u8]) -> f32 {
        let r = Reader { d: b, big_endian: self.big_endian };
        match self.datatype {
            2 => b[0] as f32,
            256 => b[0] as i8 as f32,
            4 => r.i16(0) as f32,
            512 => r.i16(0) as u16 as f32,
            8 => r.i32(0) as f32,
            768 => r.i32(0) as u32 as f32,
            16 => r.f32(0),
            _ => r.f64(0) as f32,
        }
    }
}

/// The qform affine: rotation from the quaternion (b, c, d), voxel sizes from pixdim with qfac
/// (pixdim[0] = -1 flips k), then the offsets (NIfTI-1 standard, method 2).
fn qform(r: &Reader, pixdim: &[f64]) -> [[f64; 4]; 3] {
    let (b, c, d) = (r.f32(256) as f64, r.f32(260) as f64, r.f32(264) as f64);
    let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
    let rot = [
        [a * a + b * b - c * c - d * d, 2.0 * (b * c - a * d), 2.0 * (b * d + a * c)],
        [2.0 * (b * c + a * d), a * a + c * c - b * b - d * d, 2.0 * (c * d - a * b)],
        [2.0 * (b * d - a * c), 2.0 * (c * d + a * b), a * a + d * d - b * b - c * c],
    ];
    let qfac = if pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let scale = [pixdim[1], pixdim[2], qfac * pixdim[3]];
    let offset = [r.f32(268) as f64, r.f32(272) as f64, r.f32(276) as f64];
    let mut m = [[0.0; 4]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = rot[i][j] * scale[j];
        }
        m[i][3] = offset[i];
    }
    m
}

/// Little- or big-endian fields at byte offsets.
struct Reader<'a> {
    d: &'a [u8],
    big_endian: bool,
}

impl Reader<'_> {
    fn bytes<const N: usize>(&self, o: usize) -> [u8; N] {
        let mut b = [0u8; N];
        b.copy_from_slice(&self.d[o..o + N]);
        if self.big_endian {
            b.reverse();
        }
        b
    }
    fn i16(&self, o: usize) -> i16 {
        i16::from_le_bytes(self.bytes(o))
    }
    fn i32(&self, o: usize) -> i32 {
        i32::from_le_bytes(self.bytes(o))
    }
    fn f32(&self, o: usize) -> f32 {
        f32::from_le_bytes(self.bytes(o))
    }
    fn f64(&self, o: usize) -> f64 {
        f64::from_le_bytes(self.bytes(o))
    }
}

/// Writes a little-endian NIfTI-1 `.nii` volume of float32 values with the sform and qform codes
/// set to the given affine's (scanner) frame: for tests and the synthetic head phantom.
pub fn encode(shape: [usize; 3], values: &[f32], affine: [[f64; 4]; 3]) -> Vec<u8> {
    let mut h = vec![0u8; HEADER_BYTES + 4];
    let put = |h: &mut Vec<u8>, o: usize, b: &[u8]| h[o..o + b.len()].copy_from_slice(b);
    put(&mut h, 0, &348i32.to_le_bytes());
    let dims = [3i16, shape[2] as i16, shape[1] as i16, shape[0] as i16, 1, 1, 1, 1];
    for (i, d) in dims.iter().enumerate() {
        put(&mut h, 40 + 2 * i, &d.to_le_bytes());
    }
    put(&mut h, 70, &16i16.to_le_bytes());
    put(&mut h, 72, &32i16.to_le_bytes());
    let norm = |c: usize| (0..3).map(|r| affine[r][c] * affine[r][c]).sum::<f64>().sqrt() as f32;
    for (i, v) in [1.0f32, norm(0), norm(1), norm(2)].iter().enumerate() {
        put(&mut h, 76 + 4 * i, &v.to_le_bytes());
    }
    put(&mut h, 108, &(HEADER_BYTES as f32 + 4.0).to_le_bytes());
    put(&mut h, 112, &1f32.to_le_bytes());
    h[123] = 2; // mm
    put(&mut h, 254, &1i16.to_le_bytes()); // sform_code: scanner
    for (r, row) in affine.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            put(&mut h, 280 + 16 * r + 4 * c, &(*v as f32).to_le_bytes());
        }
    }
    put(&mut h, 344, b"n+1\0");
    h.extend(values.iter().flat_map(|v| v.to_le_bytes()));
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn affine() -> [[f64; 4]; 3] {
        [[0.5, 0.0, 0.0, -10.0], [0.0, 0.75, 0.0, 20.0], [0.0, 0.0, 1.25, 5.0]]
    }

    #[test]
    fn encoded_volumes_read_back_with_shape_order_and_affine() {
        let shape = [2, 3, 4];
        let values: Vec<f32> = (0..24).map(|v| v as f32 - 3.5).collect();
        let v = parse(&encode(shape, &values, affine())).unwrap();
        assert_eq!(v.shape, shape);
        assert_eq!(v.values, values);
        assert_eq!(v.affine, affine());
    }

    #[test]
    fn gzip_big_endian_int16_with_scaling_and_qform_read_as_nibabel_does() {
        // Big-endian int16 voxels 0..8 with slope 2 and intercept -1024; qform: 180° about z
        // (quaternion b = c = 0, d = 1), voxel 1 x 2 x 3 mm, qfac -1, offsets (1, 2, 3).
        let mut h = vec![0u8; 352];
        let put = |h: &mut Vec<u8>, o: usize, b: &[u8]| h[o..o + b.len()].copy_from_slice(b);
        put(&mut h, 0, &348i32.to_be_bytes());
        for (i, d) in [3i16, 2, 2, 2, 1, 1, 1, 1].iter().enumerate() {
            put(&mut h, 40 + 2 * i, &d.to_be_bytes());
        }
        put(&mut h, 70, &4i16.to_be_bytes());
        for (i, p) in [-1f32, 1.0, 2.0, 3.0].iter().enumerate() {
            put(&mut h, 76 + 4 * i, &p.to_be_bytes());
        }
        put(&mut h, 108, &352f32.to_be_bytes());
        put(&mut h, 112, &2f32.to_be_bytes());
        put(&mut h, 116, &(-1024f32).to_be_bytes());
        put(&mut h, 252, &1i16.to_be_bytes());
        put(&mut h, 264, &1f32.to_be_bytes());
        for (i, o) in [1f32, 2.0, 3.0].iter().enumerate() {
            put(&mut h, 268 + 4 * i, &o.to_be_bytes());
        }
        put(&mut h, 344, b"n+1\0");
        h.extend((0..8i16).flat_map(|v| v.to_be_bytes()));
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut gz, &h).unwrap();
        let v = parse(&gz.finish().unwrap()).unwrap();
        assert_eq!(v.shape, [2, 2, 2]);
        assert_eq!(v.values, (0..8).map(|x| 2.0 * x as f32 - 1024.0).collect::<Vec<_>>());
        assert_eq!(v.affine, [[-1.0, 0.0, 0.0, 1.0], [0.0, -2.0, 0.0, 2.0], [0.0, 0.0, -3.0, 3.0]]);
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let good = encode([2, 2, 2], &[0.0; 8], affine());
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..100].to_vec(), "header needs 348"),
            (good[..good.len() - 4].to_vec(), "truncated"),
            (
                {
                    let mut b = good.clone();
                    b[0..4].copy_from_slice(&540i32.to_le_bytes());
                    b
                },
                "NIfTI-2",
            ),
            (
                {
                    let mut b = good.clone();
                    b[70..72].copy_from_slice(&32i16.to_le_bytes());
                    b
                },
                "data type code 32",
            ),
            (
                {
                    let mut b = good.clone();
                    b[40..42].copy_from_slice(&4i16.to_le_bytes());
                    b[48..50].copy_from_slice(&5i16.to_le_bytes());
                    b
                },
                "one 3-D volume",
            ),
            (vec![0x1f, 0x8b, 1, 2, 3], "gzip"),
        ];
        for (bytes, want) in cases {
            let e = parse(&bytes).unwrap_err();
            assert!(e.contains(want), "{e} should say {want}");
        }
    }
}
