//! `aobake inspect` on a baked asset: what it holds, read and checked
//! whole as an engine would read it (`docs/asset-format.md`).

use std::path::Path;

use anyhow::Context as _;
use aobake_core::{
    asset::Container,
    method::{
        Family, Method,
        cubemap::model::{CubemapModel, Encoding},
        grid::model::GridModel,
        texel::TexelModel,
        vertex::{Layout, Model},
    },
};
use serde::Serialize;

use super::super::common::serde_name;

/// What `aobake inspect` reports for an asset.
#[derive(Serialize)]
pub(super) struct Report {
    file: String,
    kind: &'static str,
    /// File size.
    bytes: usize,
    /// Format `major.minor`.
    format: String,
    method: Method,
    sections: Vec<SectionInfo>,
    model: ModelInfo,
    /// The JSON header as written.
    header: serde_json::Value,
}

#[derive(Serialize)]
struct SectionInfo {
    tag: String,
    #[serde(rename = "type")]
    element: &'static str,
    count: usize,
    /// Bytes of its elements.
    bytes: usize,
}

/// The model's shape, by family.
#[derive(Serialize)]
#[serde(tag = "family", rename_all = "kebab-case")]
enum ModelInfo {
    Vertex {
        vertices: usize,
        /// Weights computed per pose (`Model::weights`' length).
        weights_per_pose: usize,
        /// Bytes of the model's numbers.
        model_bytes: usize,
        /// Nodes of the rig an engine poses it by; `None` before format 1.4.
        rig_nodes: Option<usize>,
        /// Of those, the ones with a name (an engine finds the others by
        /// index).
        rig_named: Option<usize>,
        /// One line on the model's structure.
        structure: String,
    },
    Cubemap {
        clip: String,
        duration: f32,
        times: usize,
        resolution: usize,
        shells: usize,
        cubemaps: usize,
        encoding: Encoding,
        /// Texels per side of the static ground; `None`: no ground.
        ground_resolution: Option<usize>,
    },
    Grid {
        parts: Vec<PartSummary>,
        /// Cells per edge of the smallest and largest grid.
        cells_per_edge: [usize; 2],
        cones: bool,
        /// `T_clip`'s samples per axis (0 without cones).
        tclip_resolution: usize,
        /// Vertices the static base holds offsets for; `None`: no base.
        base_vertices: Option<usize>,
        /// Texels per side of the static base's ground.
        ground_resolution: Option<usize>,
    },
    Texel {
        atlas: AtlasSummary,
        /// Weights computed per pose (`Model::weights`' length).
        weights_per_pose: usize,
        /// Bytes of the model's numbers.
        model_bytes: usize,
        /// One line on the model's structure.
        structure: String,
    },
}

/// A texel asset's atlas, as `inspect` lists it.
#[derive(Serialize)]
struct AtlasSummary {
    /// Texels per row and rows.
    size: [u32; 2],
    /// Texels that hold a value (the model's columns).
    texels: usize,
    /// Atlas vertices (the character's, split where charts meet).
    vertices: usize,
}

/// A grid asset's part: its name and the palette entry (the skinning
/// matrix) that poses it.
#[derive(Serialize)]
struct PartSummary {
    name: String,
    palette_entry: usize,
}

/// Whether `path` starts with the asset magic.
pub(super) fn is_asset(path: &Path) -> anyhow::Result<bool> {
    use std::io::Read as _;
    let magic = aobake_core::asset::MAGIC;
    let mut head = Vec::with_capacity(magic.len());
    std::fs::File::open(path)
        .and_then(|f| f.take(magic.len() as u64).read_to_end(&mut head))
        .with_context(|| format!("cannot read {}", path.display()))?;
    Ok(head == magic)
}

/// Reads and checks the asset at `path`: every checksum, then the model
/// as its family's reader takes it.
pub(super) fn describe(path: &Path) -> anyhow::Result<Report> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let container =
        Container::from_bytes(&bytes).with_context(|| format!("cannot read {}", path.display()))?;
    let model = model_info(&container).with_context(|| {
        format!(
            "{} is a {} asset whose model cannot be read",
            path.display(),
            container.method
        )
    })?;
    let header = serde_json::from_str(&container.header)
        .with_context(|| format!("cannot read {}'s header", path.display()))?;
    Ok(Report {
        file: path.display().to_string(),
        kind: "asset",
        bytes: bytes.len(),
        format: format!("{}.{}", container.version.0, container.version.1),
        method: container.method,
        sections: container
            .sections
            .iter()
            .map(|s| SectionInfo {
                tag: String::from_utf8_lossy(&s.tag).into_owned(),
                element: s.data.type_name(),
                count: s.data.len(),
                bytes: s.data.byte_len(),
            })
            .collect(),
        model,
        header,
    })
}

fn model_info(container: &Container) -> anyhow::Result<ModelInfo> {
    Ok(match container.method.family() {
        Family::Vertex => {
            let (model, header) = Model::from_container(container)?;
            let rig = header.rig.as_ref();
            ModelInfo::Vertex {
                vertices: model.vertices(),
                weights_per_pose: model.weight_count(),
                model_bytes: model.bytes(),
                rig_nodes: rig.map(|r| r.nodes.len()),
                rig_named: rig.map(|r| r.nodes.iter().filter(|n| n.name.is_some()).count()),
                structure: structure(&model, &header.layout),
            }
        }
        Family::Cubemap => {
            let (model, header) = CubemapModel::from_container(container)?;
            let layout = &model.layout;
            ModelInfo::Cubemap {
                clip: header.clip,
                duration: layout.duration,
                times: layout.times,
                resolution: layout.resolution,
                shells: layout.spheroid.shells,
                cubemaps: layout.cubemaps(),
                encoding: layout.encoding,
                ground_resolution: model.ground.as_ref().map(|g| g.square.resolution),
            }
        }
        Family::Texel => {
            let (texel, header) = TexelModel::from_container(container, None)?;
            let model = &texel.model;
            ModelInfo::Texel {
                atlas: AtlasSummary {
                    size: [texel.atlas.width, texel.atlas.height],
                    texels: texel.atlas.texels.len(),
                    vertices: texel.atlas.xref.len(),
                },
                weights_per_pose: model.weight_count(),
                model_bytes: model.bytes(),
                structure: structure(model, &header.layout),
            }
        }
        Family::Grid => {
            let (model, header) = GridModel::from_container(container)?;
            let resolutions = model.parts.iter().map(|p| p.grid.resolution);
            ModelInfo::Grid {
                parts: model
                    .parts
                    .iter()
                    .map(|p| PartSummary {
                        name: p.name.clone(),
                        palette_entry: p.joint,
                    })
                    .collect(),
                cells_per_edge: [
                    resolutions.clone().min().unwrap_or(0),
                    resolutions.max().unwrap_or(0),
                ],
                cones: header.cones,
                tclip_resolution: header.tclip_resolution,
                base_vertices: model.base.as_ref().map(|b| b.vertex_offsets.len()),
                ground_resolution: model.base.as_ref().map(|b| b.ground.square.resolution),
            }
        }
    })
}

/// One line on a vertex model's structure.
fn structure(model: &Model, layout: &Layout) -> String {
    let basis = |rows: usize, sparse: bool| match (rows, sparse) {
        (0, _) => String::new(),
        (r, false) => format!("; an eigen-AO basis of {r} rows"),
        (r, true) => format!("; an eigen-AO basis of {r} sparse rows"),
    };
    match (model, layout) {
        (
            Model::VertexLinear(angles, _),
            Layout::VertexLinear {
                sparse,
                features,
                components,
                basis: rows,
                ..
            },
        ) => {
            let projection = match components {
                0 => String::new(),
                c => format!(", projected on {c} principal directions"),
            };
            format!(
                "linear in {} joint-angle parameters as {} features{projection}{}",
                angles.names.len(),
                serde_name(features),
                basis(*rows, *sparse),
            )
        }
        (
            Model::VertexClustered(handles, m),
            Layout::VertexClustered {
                base,
                basis: rows,
                sparse,
                ..
            },
        ) => format!(
            "{} pose clusters over {} handle coordinates, {} dimensions each{}{}",
            m.clusters.len(),
            handles.len(),
            m.dimensions,
            if base.is_some() {
                ", on a vertex-linear base"
            } else {
                ""
            },
            basis(*rows, *sparse),
        ),
        _ => "one occlusion per vertex, the same in every pose".into(),
    }
}

/// Prints `r` for a person.
pub(super) fn print_text(r: &Report) {
    let h = &r.header;
    let text = |key: &str| h[key].as_str().unwrap_or("?").to_owned();
    let checksums = r.sections.len() + 1;
    println!("{}", r.file);
    println!(
        "  asset        aobake asset format {}, {} bytes; all {checksums} checksums match and the model reads whole",
        r.format, r.bytes
    );
    println!(
        "  method       {} (algorithm {}), written by {}",
        r.method,
        h["algorithm_version"],
        text("generator")
    );
    println!("  bake key     {}", text("bake_key"));
    println!(
        "  character    {} (sha256 of its upload)",
        text("character")
    );
    let clips = h["clips"].as_array().map_or(0, Vec::len);
    if clips == 0 {
        println!("  clips        the character's own");
    } else {
        let uploads = if clips == 1 { "upload" } else { "uploads" };
        println!("  clips        {clips} {uploads} beside the character");
    }
    match &r.model {
        ModelInfo::Vertex {
            vertices,
            weights_per_pose,
            model_bytes,
            rig_nodes,
            rig_named,
            structure,
        } => {
            println!("  model        {vertices} vertices; {structure}");
            println!(
                "  run time     {weights_per_pose} {} per pose; the model's numbers take {model_bytes} bytes",
                if *weights_per_pose == 1 {
                    "weight"
                } else {
                    "weights"
                }
            );
            let poses = r.method != Method::StaticAverage;
            match (rig_nodes, rig_named) {
                (Some(n), _) if !poses => {
                    println!("  rig          {n} nodes (a static average reads no pose)")
                }
                (Some(n), Some(named)) if named == n => {
                    println!("  rig          {n} nodes: an engine poses it by node name")
                }
                (Some(n), Some(0)) => println!(
                    "  rig          {n} nodes, none named: an engine poses them by index (the parameters call node k `node k`)"
                ),
                (Some(n), Some(named)) => println!(
                    "  rig          {n} nodes, {named} named: an engine poses those by name and the others by index"
                ),
                (Some(n), None) => println!("  rig          {n} nodes"),
                (None, _) => println!(
                    "  rig          none (written before format 1.4): evaluate it with the character's glTF, or bake again"
                ),
            }
        }
        ModelInfo::Texel {
            atlas,
            weights_per_pose,
            model_bytes,
            structure,
        } => {
            println!(
                "  atlas        {}×{} texels, {} of them valued; {} atlas vertices",
                atlas.size[0], atlas.size[1], atlas.texels, atlas.vertices
            );
            println!("  model        per texel; {structure}");
            println!(
                "  run time     {weights_per_pose} weights per pose, then per pixel one texture fetch and multiply-add per weight; the model's numbers take {model_bytes} bytes"
            );
        }
        ModelInfo::Cubemap {
            clip,
            duration,
            times,
            resolution,
            shells,
            cubemaps,
            encoding,
            ground_resolution,
        } => {
            println!("  model        clip {clip} ({duration:.3} s) at {times} times");
            println!(
                "  cubemaps     {cubemaps}, each six {resolution}² faces ({shells} shells, {} encoding)",
                serde_name(encoding)
            );
            let s = &h["layout"]["spheroid"];
            println!(
                "  spheroid     centre {}, radii {}; shells from {} to {} × the radii",
                numbers(&s["centre"]),
                numbers(&s["radii"]),
                s["inner"],
                s["outer"]
            );
            match ground_resolution {
                Some(n) => {
                    let g = &h["ground"];
                    let q = &g["square"];
                    println!(
                        "  ground       a static ground texture of {n}² texels: corner {} (x, z), side {}, at height {}; gain {}",
                        numbers(&q["min"]),
                        q["size"],
                        q["height"],
                        g["gain"]
                    );
                }
                None => println!("  ground       none: the cubemaps alone everywhere"),
            }
        }
        ModelInfo::Grid {
            parts,
            cells_per_edge: [lo, hi],
            cones,
            tclip_resolution,
            base_vertices,
            ground_resolution,
        } => {
            let cells = if lo == hi {
                format!("{lo}³ cells each")
            } else {
                format!("{lo}³ to {hi}³ cells")
            };
            println!("  model        {} rigid parts, {cells}", parts.len());
            // Each part's palette entry: the matrix an engine passes for it.
            let named: Vec<String> = parts
                .iter()
                .map(|p| format!("{} (palette entry {})", p.name, p.palette_entry))
                .collect();
            println!("  parts        {}", named.join(", "));
            if let Some(last) = parts.iter().map(|p| p.palette_entry).max() {
                println!(
                    "  palette      at least {} matrices (the skinning palette; a rigid part's entry is its node's world matrix)",
                    last + 1
                );
            }
            if *cones {
                println!("  cones        baked, T_clip {tclip_resolution}² entries");
            } else {
                println!("  cones        none: occlusion only");
            }
            match (base_vertices, ground_resolution) {
                (Some(v), Some(g)) => {
                    println!("  static base  offsets at {v} vertices and a {g}² ground texture")
                }
                _ => println!("  static base  none: the grids alone"),
            }
        }
    }
    print_primitives(&h["primitives"]);
    println!(
        "  params       {}",
        super::super::params::shortest(h["params"].clone())
    );
    println!("  sections");
    for s in &r.sections {
        println!(
            "    {:<6} {:<4} {:>12} values {:>12} bytes",
            s.tag, s.element, s.count, s.bytes
        );
    }
}

/// The header's primitive table (vertex and grid assets from format
/// 1.6), the first few spans in full.
fn print_primitives(spans: &serde_json::Value) {
    const SHOWN: usize = 8;
    let Some(spans) = spans.as_array() else {
        return;
    };
    println!(
        "  primitives   {} glTF {} as nodes instance them, in vertex order (an engine maps its vertices by them):",
        spans.len(),
        if spans.len() == 1 {
            "primitive"
        } else {
            "primitives"
        }
    );
    for s in spans.iter().take(SHOWN) {
        let (first, count) = (
            s["first"].as_u64().unwrap_or(0),
            s["count"].as_u64().unwrap_or(0),
        );
        println!(
            "               node {} mesh {} primitive {}: vertices {first}..{}",
            s["node"],
            s["mesh"],
            s["primitive"],
            first + count
        );
    }
    if spans.len() > SHOWN {
        println!(
            "               and {} more (--json lists them all)",
            spans.len() - SHOWN
        );
    }
}

/// A JSON array of numbers as `[a, b, c]` with the f32 a person set
/// (`aobake params`' shortest form).
fn numbers(v: &serde_json::Value) -> String {
    super::super::params::shortest(v.clone()).to_string()
}
