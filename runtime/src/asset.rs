//! Any asset, read by what it holds: the one call an engine's importer
//! makes before it knows which method a file was baked with.

use crate::{
    Family, Method,
    container::{AssetError, Container},
    method::{
        cubemap::{CubemapHeader, CubemapModel},
        grid::{codec::GridHeader, model::GridModel},
        texel::TexelModel,
        vertex::{AssetHeader, VertexAo},
    },
};

/// A baked asset of any family, checked whole and ready to evaluate.
#[derive(Debug, Clone)]
pub enum Asset {
    /// Static average, vertex-linear or vertex-clustered: per-vertex AO
    /// from the local transforms of the rig's nodes.
    Vertex(Box<VertexAo>),
    /// Kroon's cubemaps: occlusion at a point at a phase of the clip.
    Cubemap {
        /// The texels and their layout.
        model: CubemapModel,
        /// The header.
        header: Box<CubemapHeader>,
    },
    /// Malmer et al.'s grids: occlusion cast by rigid parts at a point
    /// and normal, given the parts' skinning palette.
    Grid {
        /// The parts' grids.
        model: GridModel,
        /// The header.
        header: Box<GridHeader>,
    },
    /// texel-linear: the per-pose weights of a vertex method, and per
    /// texel of its atlas the coefficients they weight.
    Texel {
        /// The model and its atlas.
        model: Box<TexelModel>,
        /// The header.
        header: Box<AssetHeader>,
    },
}

impl Asset {
    /// Reads an asset of any family from its bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, AssetError> {
        let container = Container::from_bytes(bytes)?;
        Ok(match container.method.family() {
            Family::Vertex => Self::Vertex(Box::new(VertexAo::from_container(&container)?)),
            Family::Cubemap => {
                let (model, header) = CubemapModel::from_container(&container)?;
                Self::Cubemap {
                    model,
                    header: Box::new(header),
                }
            }
            Family::Grid => {
                let (model, header) = GridModel::from_container(&container)?;
                Self::Grid {
                    model,
                    header: Box::new(header),
                }
            }
            Family::Texel => {
                let (model, header) = TexelModel::from_container(&container, None)?;
                Self::Texel {
                    model: Box::new(model),
                    header: Box::new(header),
                }
            }
        })
    }

    /// The method it was baked with.
    pub fn method(&self) -> Method {
        match self {
            Self::Vertex(v) => v.header().method,
            Self::Cubemap { model, .. } => model.method(),
            Self::Grid { header, .. } => header.method,
            Self::Texel { model, .. } => model.method,
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::{
        container::AssetHeaderFields,
        method::cubemap::{CubemapLayout, Encoding, geometry::Spheroid},
    };

    #[test]
    fn reads_what_the_file_holds_and_refuses_the_rest() {
        let layout = CubemapLayout {
            spheroid: Spheroid {
                centre: Vec3::Y,
                radii: Vec3::ONE,
                outer: 1.2,
                inner: 0.2,
                shells: 2,
            },
            resolution: 2,
            times: 8,
            encoding: Encoding::Discrete,
            duration: 1.0,
        };
        let texels = (0..layout.texel_bytes()).map(|i| (i * 29) as u8).collect();
        let model = CubemapModel {
            layout,
            texels,
            ground: None,
        };
        let bytes = model
            .to_container(AssetHeaderFields::for_tests(), "walk")
            .to_bytes();
        match Asset::from_bytes(&bytes).unwrap() {
            Asset::Cubemap {
                model: read,
                header,
            } => {
                assert_eq!(read, model);
                assert_eq!(header.clip, "walk");
            }
            other => panic!("read as {:?}", other.method()),
        }
        assert_eq!(Asset::from_bytes(b"junk").unwrap_err(), AssetError::Magic);

        // Each family's own reader names another family's asset instead
        // of a field its header lacks.
        let container = Container::from_bytes(&bytes).unwrap();
        let not = |e: AssetError| match e {
            AssetError::Unsupported(m) => m,
            other => panic!("{other}"),
        };
        let e = not(GridModel::from_container(&container).unwrap_err());
        assert_eq!(e, "a cubemap-discrete asset is not a grid");
        let e = not(crate::method::vertex::Model::from_container(&container).unwrap_err());
        assert_eq!(e, "a cubemap-discrete asset is not a vertex method's");
        let e = not(VertexAo::from_container(&container).unwrap_err());
        assert_eq!(e, "a cubemap-discrete asset is not a vertex method's");
        let mut grid = container.clone();
        grid.method = crate::Method::Grid;
        let e = not(CubemapModel::from_container(&grid).unwrap_err());
        assert_eq!(e, "a grid asset is not a cubemap");
    }
}
