//! The bake parameters on the command line: named flags for the common
//! ones and `--param KEY=VALUE` for any, all of them overrides of
//! `BakeParams::new` (core keeps the only copy of every default; `aobake
//! params --method M` prints them). `aobake bake` and `aobake submit` share
//! these flags, so a local bake and a service bake of the same command
//! line have the same bake key.

use anyhow::{Context as _, bail};
use aobake_core::{bake::BakeParams, method::Method};
use serde_json::{Map, Value, json};

/// What to bake: the files, the method and its parameters. `aobake bake`
/// and `aobake submit` take the same, so a local bake and a service bake
/// of one command line have one bake key.
#[derive(Debug, Clone, clap::Args)]
pub(super) struct BakeRequestArgs {
    /// The character (.glb, or .gltf with its side files beside it).
    pub file: std::path::PathBuf,
    /// glTF files whose animations drive the character, bound to its nodes
    /// by name; the character's own clips count too.
    #[arg(long, num_args = 1..)]
    pub clips: Vec<std::path::PathBuf>,
    /// The method: vertex-linear (Kontkanen & Aila 2006), vertex-clustered
    /// (Kirk & Arikan 2007), static-average (the baseline alone),
    /// cubemap-discrete or cubemap-continuous (Kroon 2023), grid (Malmer
    /// et al. 2005), or texel-linear (vertex-linear per texel of a
    /// generated atlas; `--param texel.atlas=SIDE`).
    #[arg(long)]
    pub method: Method,
    #[command(flatten)]
    pub params: ParamArgs,
}

/// Flags that set bake parameters. Unset flags keep the method's default.
#[derive(Debug, Clone, Default, clap::Args)]
#[command(allow_negative_numbers = true)]
pub(super) struct ParamArgs {
    /// Reference poses to trace. Default: 2048 for the vertex methods, 512
    /// for texel-linear, 256 otherwise.
    #[arg(long)]
    poses: Option<usize>,
    /// Where reference poses come from: random joint angles in the clips'
    /// ranges, random clip frames, half each (mixed), half clip frames and
    /// half clip frames with every joint moved at random (perturbed, by up
    /// to `--param perturbation=F` of each range, default 0.75), or a
    /// third of each of random poses, clip frames and perturbed frames,
    /// the fit using the ones that predict left-out clips best (cv: mixed,
    /// perturbed or all). Default: cv for vertex-linear, vertex-clustered
    /// and texel-linear, clips otherwise.
    #[arg(long, value_parser = ["random", "clips", "mixed", "perturbed", "cv"])]
    reference: Option<String>,
    /// Rays per vertex (texel for texel-linear) and pose. Default: 256 (64
    /// for texel-linear).
    #[arg(long)]
    samples: Option<u32>,
    /// Hits farther than this (model units) do not occlude. Default: no
    /// limit.
    #[arg(long, allow_negative_numbers = true)]
    max_distance: Option<f32>,
    /// Seed of poses, ray directions and k-means: the same seed gives the
    /// same asset, byte for byte.
    #[arg(long)]
    seed: Option<u64>,
    /// Fit on this clip only (repeat for several). Default: every clip.
    #[arg(long = "train-clip", value_name = "NAME")]
    train_clips: Vec<String>,
    /// Hold out every frame of this clip (repeat for several). Default:
    /// every clip.
    #[arg(long = "test-clip", value_name = "NAME")]
    test_clips: Vec<String>,
    /// Held-out random poses (another seed than the reference poses).
    #[arg(long)]
    eval_poses: Option<usize>,
    /// Frame rate at which test clips are evaluated.
    #[arg(long, allow_negative_numbers = true)]
    eval_fps: Option<f32>,
    /// vertex-linear, vertex-clustered: ridge weight λ per pose on
    /// standardised pose coordinates; 0 is the pseudo-inverse.
    /// vertex-linear otherwise picks λ by cross-validation over clips:
    /// this flag fixes it (and sets linear.ridge_cv=false).
    #[arg(long, allow_negative_numbers = true)]
    ridge: Option<f64>,
    /// vertex-linear: drop coefficients whose effect is below this much AO
    /// per standard deviation of their joint angle, and store the rest
    /// sparse.
    #[arg(long, allow_negative_numbers = true)]
    threshold: Option<f32>,
    /// vertex-clustered: pose clusters m.
    #[arg(long)]
    pose_clusters: Option<usize>,
    /// vertex-clustered: PCA dimensions n per pose cluster.
    #[arg(long)]
    dimensions: Option<usize>,
    /// vertex-clustered: vertex clusters per pose cluster (0: one
    /// coefficient vector per vertex).
    #[arg(long)]
    vertex_clusters: Option<usize>,
    /// vertex-clustered: MLS blend falloff α (Kirk & Arikan Eq. 5).
    #[arg(long, allow_negative_numbers = true)]
    alpha: Option<f32>,
    /// vertex-clustered: centre each pose cluster on the global mean AO
    /// (the paper's Eq. 1) or on its own mean.
    #[arg(long, value_parser = ["global", "cluster"])]
    centering: Option<String>,
    /// vertex-clustered: clamp whitened PCA coordinates to ± this many
    /// standard deviations (0: off).
    #[arg(long, allow_negative_numbers = true)]
    clamp: Option<f32>,
    /// Any parameter by its name in `aobake params` (dotted for method
    /// options, such as `clustered.vertex_tolerance=0.01`); the value is
    /// JSON, or a string when it is not. Repeat for several.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    params: Vec<String>,
}

impl ParamArgs {
    /// The flags as an overrides object for `BakeParams::with_overrides`.
    pub(super) fn overrides(&self, method: Method) -> anyhow::Result<Map<String, Value>> {
        let mut m = Map::new();
        let mut set = |k: &str, v: Value| {
            m.insert(k.to_owned(), v);
        };
        macro_rules! opt {
            ($field:ident, $key:expr) => {
                if let Some(v) = &self.$field {
                    set($key, json!(v));
                }
            };
        }
        opt!(poses, "poses");
        opt!(reference, "reference");
        opt!(samples, "samples");
        opt!(max_distance, "max_distance");
        opt!(seed, "seed");
        opt!(eval_poses, "eval_poses");
        opt!(eval_fps, "eval_fps");
        opt!(threshold, "linear.threshold");
        opt!(pose_clusters, "clustered.pose_clusters");
        opt!(dimensions, "clustered.dimensions");
        opt!(vertex_clusters, "clustered.vertex_clusters");
        opt!(alpha, "clustered.alpha");
        opt!(centering, "clustered.centering");
        opt!(clamp, "clustered.clamp");
        if let Some(r) = self.ridge {
            match method {
                Method::VertexClustered => set("clustered.ridge", json!(r)),
                // The ridge given, not one cross-validation picks
                // (`--param linear.ridge_cv=true` below keeps it picking).
                Method::VertexLinear => {
                    set("linear.ridge", json!(r));
                    set("linear.ridge_cv", json!(false));
                }
                _ => bail!(
                    "--ridge is an option of vertex-linear and vertex-clustered, not {method}"
                ),
            }
        }
        if !self.train_clips.is_empty() {
            set("train_clips", json!(self.train_clips));
        }
        if !self.test_clips.is_empty() {
            set("test_clips", json!(self.test_clips));
        }
        for kv in &self.params {
            let Some((k, v)) = kv.split_once('=') else {
                bail!("--param {kv:?} is not KEY=VALUE");
            };
            let value = serde_json::from_str(v).unwrap_or_else(|_| Value::String(v.to_owned()));
            set(k.trim(), value);
        }
        Ok(m)
    }

    /// The fully defaulted, validated parameters.
    pub(super) fn params(&self, method: Method) -> anyhow::Result<BakeParams> {
        BakeParams::with_overrides(method, &self.overrides(method)?)
            .context("the bake parameters are not valid")
    }
}

/// Arguments of `aobake params`.
#[derive(Debug, clap::Args)]
pub(super) struct Args {
    /// The method whose defaults to print.
    #[arg(long)]
    method: Method,
    #[command(flatten)]
    params: ParamArgs,
}

/// Prints the method's fully defaulted parameters (with any flags
/// applied) as JSON: the common ones and the method's own section, as the
/// bake key and the asset have them.
pub(super) fn run(args: &Args) -> anyhow::Result<()> {
    let p = args.params.params(args.method)?;
    println!(
        "{}",
        serde_json::to_string_pretty(&shortest(p.canonical()))?
    );
    Ok(())
}

/// `v` with every number that is an f32 (the parameters' floats, widened)
/// written as that f32's shortest decimal, as a person set it: 0.1, not
/// 0.10000000149011612. Read back as an f32 it is the same value.
pub(super) fn shortest(v: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match v {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().expect("an f64");
            let narrow = x as f32;
            if f64::from(narrow) != x {
                return Value::Number(n);
            }
            narrow
                .to_string()
                .parse::<f64>()
                .ok()
                .and_then(serde_json::Number::from_f64)
                .map_or(Value::Number(n), Value::Number)
        }
        Value::Array(a) => Value::Array(a.into_iter().map(shortest).collect()),
        Value::Object(o) => Value::Object(o.into_iter().map(|(k, v)| (k, shortest(v))).collect()),
        other => other,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn floats_print_as_the_f32_a_person_set() {
        let v = serde_json::json!({"a": f64::from(0.1f32), "b": [f64::from(0.6f32), 3], "c": 0.1, "d": 1e-3});
        let tidy = super::shortest(v);
        assert_eq!(
            tidy.to_string(),
            r#"{"a":0.1,"b":[0.6,3],"c":0.1,"d":0.001}"#
        );
        // The same f32 when read back.
        assert_eq!(tidy["a"].as_f64().unwrap() as f32, 0.1f32);
    }
}
