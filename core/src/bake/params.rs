//! [`BakeParams`]: everything that determines a bake besides its inputs,
//! and the only place their defaults live. The CLI's flags and `--param`
//! and the HTTP API's `params` object are both partial overrides of
//! [`BakeParams::new`], applied by [`BakeParams::with_overrides`] and
//! checked by [`BakeParams::validate`]; the fully defaulted value enters
//! the bake key.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::{
    digest::sha256_hex,
    method::{
        Family, Method,
        cubemap::CubemapOptions,
        grid::GridOptions,
        texel::TexelOptions,
        vertex::{ClusteredOptions, LinearOptions},
    },
    pose_space::ParamError,
    trace::{Falloff, HELD_OUT_SEED, SurfaceParams},
};

/// Mixed into the ray seed of the noise estimate ("noise!!!").
const NOISE_SEED: u64 = 0x6e6f_6973_6521_2121;

/// Where reference (training) poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceSource {
    /// Every joint angle uniform in its range (Kontkanen & Aila).
    Random,
    /// Random times in the training clips (Kirk & Arikan train on clip
    /// frames).
    Clips,
    /// Half of each.
    Mixed,
    /// Half random training-clip frames, half clip frames with every joint
    /// parameter moved by a uniform offset of up to ±`perturbation` of its
    /// range (clamped to it): poses like motion whose joints still vary
    /// independently.
    Perturbed,
    /// A third each of random poses, clip frames and perturbed clip
    /// frames; the fit's cross-validation over clips chooses which it
    /// uses: random poses and frames (as `mixed`), frames and perturbed
    /// frames (as `perturbed`), or all three (see
    /// `method::vertex::cv::choose_rows`).
    Cv,
}

/// Everything that determines a bake besides its inputs. The
/// fully defaulted value goes into the bake key and the asset header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BakeParams {
    /// The method.
    pub method: Method,
    /// Reference poses to fit to.
    pub poses: usize,
    /// Where they come from (default: `cv` for the vertex methods, clip
    /// frames otherwise).
    pub reference: ReferenceSource,
    /// The largest offset of a perturbed reference pose's parameters, as
    /// a fraction of each parameter's range.
    pub perturbation: f32,
    /// Rays per vertex and pose.
    pub samples: u32,
    /// Hits farther than this (model units) do not occlude; `None`: no
    /// limit.
    pub max_distance: Option<f32>,
    /// Seed of poses, rays and k-means.
    pub seed: u64,
    /// Clips whose poses train the model (empty: all).
    pub train_clips: Vec<String>,
    /// Clips whose every frame is a held-out test (empty: all).
    pub test_clips: Vec<String>,
    /// Held-out random poses (joint angles uniform in the training
    /// clips' ranges, another seed).
    pub eval_poses: usize,
    /// Frame rate at which test clips are evaluated.
    pub eval_fps: f32,
    /// Most clips the unseen-clips evaluation leaves out in turn (leave
    /// one clip out; 0: none).
    pub eval_folds: usize,
    /// Joint-angle ranges: the training clips' range widened by this
    /// fraction of its span on each side.
    pub range_margin: f32,
    /// Animated node scales are pose parameters too (per axis, the scale
    /// over the rest scale minus 1), beside joint rotations and root
    /// translations. Default: on for the vertex methods, off otherwise.
    pub scale_parameters: bool,
    /// vertex-linear options.
    pub linear: LinearOptions,
    /// vertex-clustered options.
    pub clustered: ClusteredOptions,
    /// Cubemap options (both cubemap methods).
    pub cubemap: CubemapOptions,
    /// Grid options.
    pub grid: GridOptions,
    /// Texel options (the atlas; the fit reads `linear`).
    pub texel: TexelOptions,
}

impl BakeParams {
    /// Defaults for a method.
    pub fn new(method: Method) -> Self {
        Self {
            method,
            // The vertex methods' matrix features and linear base keep
            // gaining from more poses on clips they never saw (Fox's
            // vertex-linear: +2.6 dB over the static average with 256,
            // +3.3 with 512, +4.0 with 1024 of mixed poses;
            // RobotExpressive's +2.8 and +3.3 with 512 and 1024; docs/methods/vertex.md).
            // With `cv`, 2048 are about 683 of each source, and a fit uses
            // two thirds or all of them. 1536 (1024 rows) left
            // InterpolationTest's most distinct unseen clip at +1.87 dB
            // over the static average; 2048 lifts it past +2.3 at seeds
            // 0–2 for a third more tracing (docs/methods/vertex.md).
            // texel-linear: a texel costs a vertex's rays, and an atlas
            // holds tens of times more texels than a character vertices;
            // 512 poses × 64 rays judged the Kenney character's texel model
            // at half of GTAO's per-pixel error on training clips
            // (docs/methods/texel.md).
            poses: match method.family() {
                Family::Texel => 512,
                _ if method.fits_poses() => 2048,
                _ => 256,
            },
            // Random joint angles alone combine every joint's extremes and
            // fit clip poses poorly (Fox: +0.5 dB over the baseline on
            // clip frames against +9 dB with half clip frames); clip frames
            // alone leave correlated angles that random poses decorrelate.
            // Perturbed frames instead of random poses win on some
            // characters (InterpolationTest's unseen clips: +3.6 dB against
            // +3.0) and lose on others (Fox: +2.3 against +4.0), so the
            // cross-validation over clips chooses per bake (docs/methods/vertex.md).
            // vertex-clustered's linear base is fitted to them too.
            reference: if method.fits_poses() {
                ReferenceSource::Cv
            } else {
                ReferenceSource::Clips
            },
            // Perturbed frames at ±25 % of the ranges barely differed
            // from plain ones; ±75 % won on InterpolationTest (docs/methods/vertex.md).
            perturbation: 0.75,
            samples: match method.family() {
                Family::Texel => 64,
                _ => 256,
            },
            max_distance: None,
            seed: 0,
            train_clips: Vec::new(),
            test_clips: Vec::new(),
            eval_poses: 32,
            // Every held-out clip frame is traced at every receiver: at
            // 10 frames a second the texel evaluation costs a third of
            // the reference trace on the Kenney character's 32 clips.
            eval_fps: match method.family() {
                Family::Texel => 10.0,
                _ => 30.0,
            },
            eval_folds: 8,
            range_margin: 0.1,
            // On InterpolationTest's unseen clips (three of which only
            // scale a cube) they lift vertex-linear from +2.14 to +2.96 dB
            // and vertex-clustered's worst clip from +0.09 to +0.67
            // (docs/methods/vertex.md).
            scale_parameters: method.fits_poses(),
            linear: LinearOptions::default(),
            clustered: ClusteredOptions::default(),
            cubemap: CubemapOptions::default(),
            grid: GridOptions::default(),
            texel: TexelOptions::default(),
        }
    }

    /// The tracing parameters of the reference poses.
    pub fn surface(&self) -> SurfaceParams {
        SurfaceParams {
            samples: self.samples,
            max_distance: self.max_distance.unwrap_or(f32::INFINITY),
            seed: self.seed,
            falloff: Falloff::None,
        }
    }

    /// The tracing parameters of the held-out poses: another ray seed, so
    /// that the ground truth's sampling noise is independent of the noise
    /// the model was fitted to (with the same seed a vertex would cast the
    /// same rays in both, and errors would come out too small).
    pub fn held_out_surface(&self) -> SurfaceParams {
        SurfaceParams {
            seed: self.seed ^ HELD_OUT_SEED,
            ..self.surface()
        }
    }

    /// The tracing parameters of the second trace that estimates the
    /// ground truth's noise: independent of both other seeds.
    pub fn noise_surface(&self) -> SurfaceParams {
        SurfaceParams {
            seed: self.seed ^ NOISE_SEED,
            ..self.surface()
        }
    }

    /// Eq. 3.1's parameters of a cubemap's ground truth around
    /// `spheroid` (the previews' ground): the evaluation's rays, the
    /// held-out seed.
    pub fn cubemap_truth(
        &self,
        spheroid: &crate::method::cubemap::geometry::Spheroid,
    ) -> crate::trace::KroonParams {
        crate::trace::KroonParams {
            samples: self.cubemap.eval_rays,
            ..self.cubemap.kroon(spheroid, self.seed ^ HELD_OUT_SEED)
        }
    }

    /// The parameters as they enter the key and as assets, bakes and
    /// `aobake params` show them: only the chosen method's options.
    pub fn canonical(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).expect("params serialise");
        let map = v.as_object_mut().expect("an object");
        // Each method keeps its own options' block, and only that one.
        map.retain(|key, _| !foreign_block(self.method, key));
        v
    }
}

/// The methods' option blocks.
const BLOCKS: [&str; 5] = ["linear", "clustered", "cubemap", "grid", "texel"];

/// Whether `key` (a top-level parameter name) is the option block of
/// another method than `method`: one it neither reads nor keys on.
fn foreign_block(method: Method, key: &str) -> bool {
    BLOCKS.contains(&key) && !own_blocks(method).contains(&key)
}

/// The blocks of options `method` reads.
fn own_blocks(method: Method) -> &'static [&'static str] {
    match method {
        Method::StaticAverage => &[],
        Method::VertexLinear => &["linear"],
        Method::VertexClustered => &["clustered"],
        Method::CubemapDiscrete | Method::CubemapContinuous => &["cubemap"],
        Method::Grid => &["grid"],
        Method::TexelLinear => &["linear", "texel"],
    }
}

/// Why a bake cannot run; each names the offending input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BakeError {
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    Param(String),
    /// The character cannot be parameterised.
    #[error(transparent)]
    Layout(#[from] ParamError),
    /// An override names no parameter, or has the wrong type.
    #[error("invalid params: {0}")]
    Override(String),
    /// The fit failed; the message says what to change.
    #[error("{0}")]
    Fit(String),
    /// A named clip does not exist.
    #[error("no clip named {name:?}; the clips are: {known}")]
    UnknownClip {
        /// The name asked for.
        name: String,
        /// The names there are.
        known: String,
    },
}

impl BakeParams {
    /// The defaults for `method` with `overrides` applied: a JSON object
    /// whose keys are parameter names (nested objects for the method
    /// options, such as `{"clustered": {"alpha": 5}}`, or dotted keys such
    /// as `"clustered.alpha"`). Unknown keys and wrong types are refused
    /// by name; the result is validated.
    pub fn with_overrides(
        method: Method,
        overrides: &Map<String, Value>,
    ) -> Result<Self, BakeError> {
        let mut value = serde_json::to_value(Self::new(method)).expect("params serialise");
        // The names a typo is matched against: this method's own.
        let mut known = Vec::new();
        leaf_paths(&value, "", &mut known);
        known.retain(|k| !foreign_block(method, k.split('.').next().unwrap_or_default()));
        let names = Names { method, known };
        for (key, v) in overrides {
            if key == "method" {
                if v.as_str() != Some(method.name()) {
                    return Err(BakeError::Override(format!(
                        "params.method ({v}) differs from the bake's method ({method})"
                    )));
                }
                continue;
            }
            let path: Vec<&str> = key.split('.').collect();
            // Another method's option would be dropped from the key and
            // never read: a mistake to name, not to ignore.
            if foreign_block(method, path[0]) {
                let whose: Vec<&str> = Method::ALL
                    .into_iter()
                    .filter(|&m| own_blocks(m).contains(&path[0]))
                    .map(Method::name)
                    .collect();
                return Err(BakeError::Override(format!(
                    "{key:?} is an option of {}; a {method} bake does not take it{}",
                    whose.join(" and "),
                    match own_blocks(method) {
                        [] => String::new(),
                        own => format!(" (its own are under \"{}\")", own.join("\" and \"")),
                    }
                )));
            }
            merge(&mut value, &path, v.clone(), key, &names)?;
        }
        let params: Self =
            serde_json::from_value(value).map_err(|e| BakeError::Override(e.to_string()))?;
        params.validate()?;
        Ok(params)
    }

    /// Reads parameters as [`canonical`](Self::canonical) writes them (an
    /// asset's header, a bake's row): the method's own sections, the
    /// others filled with their defaults.
    pub fn from_canonical(value: &Value) -> Result<Self, BakeError> {
        let map = value
            .as_object()
            .ok_or_else(|| BakeError::Override("the parameters are not an object".into()))?;
        let method: Method = map
            .get("method")
            .cloned()
            .map(serde_json::from_value)
            .transpose()
            .map_err(|e| BakeError::Override(format!("method: {e}")))?
            .ok_or_else(|| BakeError::Override("the parameters name no method".into()))?;
        // Another method's block is not read (and was not written by
        // `canonical`): a header that has one is read without it.
        let mut map = map.clone();
        map.retain(|key, _| !foreign_block(method, key));
        Self::with_overrides(method, &map)
    }

    /// Checks every parameter's range; the error names the parameter.
    pub fn validate(&self) -> Result<(), BakeError> {
        let p = self;
        if p.poses == 0 || p.poses > 100_000 {
            return Err(BakeError::Param(format!(
                "poses must be between 1 and 100000, not {}",
                p.poses
            )));
        }
        if p.eval_poses > 100_000 {
            return Err(BakeError::Param(format!(
                "eval_poses must be at most 100000, not {}",
                p.eval_poses
            )));
        }
        if p.samples == 0 || p.samples > crate::trace::MAX_SAMPLES {
            return Err(BakeError::Param(format!(
                "samples must be between 1 and {}, not {}",
                crate::trace::MAX_SAMPLES,
                p.samples
            )));
        }
        if p.max_distance.is_some_and(|d| d.is_nan() || d <= 0.0) {
            return Err(BakeError::Param("max_distance must be positive".into()));
        }
        if p.eval_folds > 64 {
            return Err(BakeError::Param(format!(
                "eval_folds must be at most 64, not {}",
                p.eval_folds
            )));
        }
        if !(p.eval_fps > 0.0 && p.eval_fps <= 240.0) {
            return Err(BakeError::Param("eval_fps must be in (0, 240]".into()));
        }
        if !(p.perturbation >= 0.0 && p.perturbation <= 1.0) {
            return Err(BakeError::Param("perturbation must be in [0, 1]".into()));
        }
        if !(p.range_margin >= 0.0 && p.range_margin <= 10.0) {
            return Err(BakeError::Param("range_margin must be in [0, 10]".into()));
        }
        if !(p.linear.ridge >= 0.0 && p.linear.ridge.is_finite()) {
            return Err(BakeError::Param("ridge must be a finite number ≥ 0".into()));
        }
        if !(p.linear.threshold >= 0.0 && p.linear.threshold.is_finite()) {
            return Err(BakeError::Param(
                "threshold must be a finite number ≥ 0".into(),
            ));
        }
        let c = &p.clustered;
        if c.pose_clusters == 0 || c.pose_clusters > 1024 {
            return Err(BakeError::Param(
                "pose_clusters must be between 1 and 1024".into(),
            ));
        }
        if c.dimensions == 0 || c.dimensions > 256 {
            return Err(BakeError::Param(
                "dimensions must be between 1 and 256".into(),
            ));
        }
        if !(c.alpha > 0.0 && c.alpha <= 100.0) {
            return Err(BakeError::Param("alpha must be in (0, 100]".into()));
        }
        if !(c.vertex_tolerance >= 0.0 && c.vertex_tolerance.is_finite()) {
            return Err(BakeError::Param(
                "vertex_tolerance must be a finite number ≥ 0".into(),
            ));
        }
        if !(c.ridge >= 0.0 && c.ridge.is_finite()) {
            return Err(BakeError::Param("ridge must be a finite number ≥ 0".into()));
        }
        if !(c.clamp >= 0.0 && c.clamp.is_finite()) {
            return Err(BakeError::Param("clamp must be a finite number ≥ 0".into()));
        }
        p.cubemap.validate().map_err(BakeError::Param)?;
        p.grid.validate().map_err(BakeError::Param)?;
        p.texel.validate().map_err(BakeError::Param)?;
        if p.method.family() == Family::Texel
            && (p.linear.threshold != 0.0 || p.linear.basis_threshold != 0.0)
        {
            return Err(BakeError::Param(
                "linear.threshold and linear.basis_threshold must be 0 for texel-linear: a texture holds every texel, so dropping small coefficients saves nothing"
                    .into(),
            ));
        }
        let layers = aobake_runtime::method::texel::MAX_TEXTURES;
        if p.method.family() == Family::Texel && !(1..layers).contains(&p.linear.basis) {
            return Err(BakeError::Param(format!(
                "linear.basis must be 1 to {} for texel-linear: each weight is a texture, one layer of an array that GPUs hold at most {layers} of, not {}",
                layers - 1,
                p.linear.basis
            )));
        }
        if p.method.family() == Family::Texel
            && p.linear.locality != crate::method::vertex::Locality::Off
        {
            return Err(BakeError::Param(
                "linear.locality must be off for texel-linear: a texel's joints are not gathered yet"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Ray-point pairs the bake traces for a character of `vertices`
    /// vertices with `test_frames` clip frames held out and `parts` rigid
    /// parts (a cubemap bake: the rays of its sample points and its
    /// evaluation; a grid bake: its cells and its evaluation): what the
    /// service bounds per request (`Bake::work` counts the inputs).
    pub fn work(&self, vertices: usize, test_frames: usize, parts: usize) -> u128 {
        match self.method.family() {
            Family::Cubemap => self.cubemap.rays_total(),
            Family::Grid => self.grid.rays_total(parts, vertices),
            // `vertices`: the receivers, a texel bake's texels.
            Family::Vertex | Family::Texel => {
                let poses = self.poses + self.eval_poses + test_frames + NOISE_POSES;
                poses as u128 * vertices as u128 * u128::from(self.samples)
            }
        }
    }
}

/// Held-out poses traced twice to estimate the ground truth's noise.
pub(crate) const NOISE_POSES: usize = 8;

/// A method's parameter names, for the hint of an unknown one.
struct Names {
    method: Method,
    /// Dotted paths of its leaves (`linear.ridge`).
    known: Vec<String>,
}

impl Names {
    /// The refusal of `key`, with the nearest names (a typo's fix, or the
    /// same last part under its section: `rays` → `grid.rays`) and where
    /// to see them all.
    fn unknown(&self, key: &str) -> BakeError {
        let last = key.rsplit('.').next().unwrap_or(key);
        // What the vertex methods call samples, the volume methods call
        // rays.
        let synonym = match last {
            "rays" => "samples",
            "samples" => "rays",
            _ => last,
        };
        let mut near: Vec<(usize, &str)> = self
            .known
            .iter()
            .filter_map(|k| {
                let d = strsim::damerau_levenshtein(key, k);
                let same_last = k
                    .rsplit('.')
                    .next()
                    .is_some_and(|t| t == last || t == synonym);
                (d <= (key.len() / 3).max(2) || same_last).then_some((d, k.as_str()))
            })
            .collect();
        near.sort_unstable();
        near.truncate(3);
        let hint = match near.as_slice() {
            [] => String::new(),
            [(_, one)] => format!("; did you mean \"{one}\"?"),
            many => format!(
                "; did you mean one of \"{}\"?",
                many.iter()
                    .map(|(_, k)| *k)
                    .collect::<Vec<_>>()
                    .join("\", \"")
            ),
        };
        BakeError::Override(format!(
            "unknown parameter {key:?}{hint} (`aobake params --method {}` lists them all)",
            self.method
        ))
    }
}

/// Every leaf of `value` as a dotted path under `prefix`.
fn leaf_paths(value: &Value, prefix: &str, out: &mut Vec<String>) {
    match value.as_object() {
        Some(map) => {
            for (k, v) in map {
                let path = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                leaf_paths(v, &path, out);
            }
        }
        None => out.push(prefix.to_owned()),
    }
}

/// Sets `path` in `value` (an object) to `v`, refusing keys the defaults
/// do not have so that a typo is an error, not a silently ignored option.
fn merge(
    value: &mut Value,
    path: &[&str],
    v: Value,
    key: &str,
    names: &Names,
) -> Result<(), BakeError> {
    let Some((first, rest)) = path.split_first() else {
        return Ok(());
    };
    let Some(slot) = value.as_object_mut().and_then(|m| m.get_mut(*first)) else {
        return Err(names.unknown(key));
    };
    if rest.is_empty() {
        match (slot.is_object(), v) {
            (true, Value::Object(inner)) => {
                for (k, x) in inner {
                    merge(slot, &[k.as_str()], x, &format!("{key}.{k}"), names)?;
                }
            }
            (_, v) => *slot = v,
        }
        Ok(())
    } else {
        merge(slot, rest, v, key, names)
    }
}

/// The bake key (DESIGN §1.2): sha256 over the canonical JSON (keys sorted,
/// no whitespace) of the input digests, the method, the fully defaulted
/// parameters and the algorithm version.
pub fn bake_key(character: &str, clips: &[String], params: &BakeParams) -> String {
    let request = serde_json::json!({
        "algorithm_version": crate::method::algorithm_version(params.method),
        "character": character,
        "clips": clips,
        "method": params.method,
        "params": params.canonical(),
    });
    sha256_hex(request.to_string().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOLDEN_KEY: &str = "33084f15b4c5874e3c3b98df9b743404e3f1a4357488214ca8d8f25b605561cf";

    #[test]
    fn another_methods_options_are_refused_by_name_and_the_own_read() {
        let o = |v: Value| v.as_object().unwrap().clone();
        for (method, key) in [
            (Method::VertexLinear, "clustered.alpha"),
            (Method::VertexClustered, "linear.ridge"),
            (Method::Grid, "cubemap.resolution"),
            (Method::StaticAverage, "grid.rays"),
        ] {
            let e = BakeParams::with_overrides(method, &o(serde_json::json!({ key: 3 })))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(key) && e.contains(&format!("a {method} bake does not take it")),
                "{e}"
            );
            // The whole block, as JSON, too.
            let (block, option) = key.split_once('.').unwrap();
            let nested = serde_json::json!({ block: { option: 3 } });
            assert!(BakeParams::with_overrides(method, &o(nested)).is_err());
        }
        let p = BakeParams::with_overrides(
            Method::VertexClustered,
            &o(serde_json::json!({"clustered.alpha": 3.0})),
        )
        .unwrap();
        assert_eq!(p.clustered.alpha, 3.0);
        // An asset's header (its method's block only) reads back, and one
        // with every block (as a writer that kept them would have it)
        // reads as the method's own.
        assert_eq!(BakeParams::from_canonical(&p.canonical()).unwrap(), p);
        let every = serde_json::to_value(&p).unwrap();
        assert_eq!(BakeParams::from_canonical(&every).unwrap(), p);
    }

    #[test]
    fn key_depends_on_what_matters_only() {
        let a = BakeParams::new(Method::VertexLinear);
        let k = bake_key("c", &[], &a);
        assert_eq!(k.len(), 64);
        assert_eq!(k, bake_key("c", &[], &a.clone()));
        assert_ne!(k, bake_key("d", &[], &a));
        let mut b = a.clone();
        b.seed = 1;
        assert_ne!(k, bake_key("c", &[], &b));
        // Options of another method do not change the key.
        let mut c = a.clone();
        c.clustered.alpha = 3.0;
        assert_eq!(k, bake_key("c", &[], &c));
        // Pinned: a change here invalidates every cached bake, so it must be
        // deliberate (and come with an ALGORITHM_VERSION bump if fitting
        // changed).
        assert_eq!(
            k,
            bake_key("c", &[], &BakeParams::new(Method::VertexLinear)),
        );
        assert_eq!(
            bake_key("c", &[], &BakeParams::new(Method::VertexLinear)),
            GOLDEN_KEY
        );
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
