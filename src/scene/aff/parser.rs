//! The command loop: one pass over each file's tokens, recursing into includes, emitting
//! nodes, geometry, materials and key blocks into the scene being built.
//!
//! Commands are whole tokens (FORMAT.md 1.2). Supported: `v b l la am a f fm c s p pp tt
//! ttp tpa m i d xs x } k`. Anything else is an error naming the file and line.

use std::collections::HashMap;
use std::path::Path;

use glam::{Quat, Vec2, Vec3};

use super::AffStats;
use super::builder::{Builder, Geometry, MorphTriangle};
use super::camera::View;
use super::includes::{Files, include_candidates, texture_candidates};
use super::lexer::Token;
use super::materials::{Fm, Materials};
use super::mesh::read_mesh;
use super::reader::Reader;
use super::shapes;
use super::tracks::{KeyBlock, PositionKey, RotationKey, Tcb, VisibilityKey};
use crate::scene::{FrameTimes, Trs};

/// Largest vertex or sample count of one polygon / `tpa` / key list (a guard against
/// absurd allocations in malformed files).
const MAX_ITEMS: usize = 1 << 24;

/// Largest sample count of one `tpa` (BART's museum uses 5). A run of `tpa`s with `k`
/// samples becomes one morphing mesh whose weights channel holds `k (k - 1)` values, so
/// this bounds that channel to 256 KB however few bytes declare it.
pub const MAX_MORPH_SAMPLES: usize = 256;

/// A point light from `l` (or `la`, whose name is kept).
#[derive(Debug, Clone)]
pub struct PointLight {
    pub position: Vec3,
    pub color: Vec3,
    pub name: Option<String>,
}

/// Parser state: the global AFF state (material, detail level, transform stack) and
/// everything collected so far.
pub struct Parser {
    pub builder: Builder,
    pub materials: Materials,
    pub files: Files,
    pub main_dir: std::path::PathBuf,
    /// The current `fm` (global: not scoped by `{}` or includes).
    pub fm: Option<Fm>,
    /// Open transform nodes; `scopes[0]` is the root geometry node.
    pub scopes: Vec<usize>,
    /// Animated transform nodes (`x name`) with their names.
    pub x_nodes: Vec<(usize, String)>,
    /// `k` blocks by name, the last parsed wins.
    pub key_blocks: HashMap<String, KeyBlock>,
    pub view: Option<View>,
    pub background: Option<Vec3>,
    pub ambient: Option<Vec3>,
    pub frame_times: Option<FrameTimes>,
    pub lights: Vec<PointLight>,
    pub detail: i64,
    pub stats: AffStats,
    pub notes: Vec<String>,
    /// Key tracks whose times go back somewhere.
    pub tracks_going_back: usize,
}

/// `a start end frames`: the scene's frame times.
fn frame_times(r: &mut Reader) -> Result<FrameTimes, String> {
    let start = r.number("a")?;
    let end = r.number("a")?;
    let frames = r.count("a", u32::MAX as usize)? as u32;
    Ok(FrameTimes { start, end, frames })
}

/// `f r g b kd ks shine transmission ior`: NFF's material, as the `fm` state it stands for.
fn nff_material(r: &mut Reader) -> Result<Fm, String> {
    let color = r.vec3("f")?;
    let kd = r.number("f")?;
    let ks = r.number("f")?;
    let shine = r.number("f")?;
    let transmission = r.number("f")?;
    let ior = r.number("f")?;
    Ok(Fm {
        ambient: Vec3::ZERO,
        diffuse: color * kd,
        specular: Vec3::splat(ks),
        shine,
        transmission,
        ior,
    })
}

/// `fm ambient diffuse specular shine transmission ior`.
fn fm_material(r: &mut Reader) -> Result<Fm, String> {
    Ok(Fm {
        ambient: r.vec3("fm")?,
        diffuse: r.vec3("fm")?,
        specular: r.vec3("fm")?,
        shine: r.number("fm")?,
        transmission: r.number("fm")?,
        ior: r.number("fm")?,
    })
}

fn tcb(r: &mut Reader, after: &str) -> Result<Tcb, String> {
    Ok(Tcb {
        tension: r.number(after)?,
        continuity: r.number(after)?,
        bias: r.number(after)?,
    })
}

/// Checks that key times never decrease.
fn check_times(
    r: &Reader,
    line: u32,
    motion: &str,
    times: impl Iterator<Item = f32>,
) -> Result<(), String> {
    let mut last = f32::NEG_INFINITY;
    for t in times {
        if t < last {
            return Err(r.error_at(
                line,
                format!("'{motion}' key times decrease ({t} after {last})"),
            ));
        }
        last = t;
    }
    Ok(())
}

impl Parser {
    pub fn new(main_dir: std::path::PathBuf, root_name: String) -> Self {
        let mut builder = Builder::default();
        let root = builder.add_node(None, root_name, Trs::default());
        Parser {
            builder,
            materials: Materials::default(),
            files: Files::default(),
            main_dir,
            fm: None,
            scopes: vec![root],
            x_nodes: Vec::new(),
            key_blocks: HashMap::new(),
            view: None,
            background: None,
            ambient: None,
            frame_times: None,
            lights: Vec::new(),
            detail: 0,
            stats: AffStats::default(),
            notes: Vec::new(),
            tracks_going_back: 0,
        }
    }

    fn scope(&self) -> usize {
        // `}` never pops the root scope (index 0), so this is the root at worst.
        self.scopes.last().copied().unwrap_or(0)
    }

    /// Parses one file (the caller has checked it exists); `name` is used in messages.
    pub fn parse_file(&mut self, path: &Path, name: &str) -> Result<(), String> {
        self.files.enter(path, name)?;
        let bytes = self.files.read(path)?;
        let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut r = Reader::new(&bytes, name);
        while let Some(token) = r.next() {
            self.command(&mut r, token, &dir)?;
        }
        self.files.leave();
        Ok(())
    }

    fn material(&mut self, texture: Option<usize>) -> usize {
        self.materials.material(self.fm.as_ref(), texture)
    }

    fn texture(&mut self, r: &Reader, name: &str, line: u32, dir: &Path) -> Result<usize, String> {
        let candidates = texture_candidates(dir, &self.main_dir, name);
        self.materials
            .texture(name, &candidates, &mut self.files)
            .map_err(|e| r.error_at(line, e))
    }

    fn add(&mut self, material: usize, g: Geometry) -> usize {
        let triangles = g.indices.len() / 3;
        let node = self.scope();
        self.builder.add_geometry(node, material, g);
        triangles
    }

    fn command(&mut self, r: &mut Reader, token: Token, dir: &Path) -> Result<(), String> {
        let line = token.line;
        match token.text {
            // Scene-wide settings.
            b"v" => self.view(r)?,
            b"b" => self.background = Some(r.colour("b")?),
            b"am" => self.ambient = Some(r.colour("am")?),
            b"a" => self.frame_times = Some(frame_times(r)?),
            b"l" => self.light(r, None)?,
            b"la" => {
                let name = r.name("la")?.0;
                self.light(r, Some(name))?;
            }
            // Material state.
            b"f" => self.set_material(nff_material(r)?),
            b"fm" => self.set_material(fm_material(r)?),
            // Geometry.
            b"c" => self.cone(r)?,
            b"s" => self.sphere(r)?,
            b"p" => self.polygon(r, "p")?,
            b"pp" => self.polygon(r, "pp")?,
            b"tt" => self.textured_triangle(r, "tt", dir)?,
            b"ttp" => self.textured_triangle(r, "ttp", dir)?,
            b"tpa" => self.tpa(r, line)?,
            b"m" => self.mesh(r, dir)?,
            // Files and detail.
            b"i" => self.include(r, dir)?,
            b"d" => self.detail = r.int("d")?,
            // Transform blocks and their key tracks.
            b"xs" => self.static_transform(r)?,
            b"x" => self.animated_transform(r)?,
            b"}" => {
                if self.scopes.len() <= 1 {
                    return Err(r.error_at(line, "'}' without an open 'x' or 'xs'"));
                }
                self.scopes.pop();
            }
            b"k" => self.key_block(r)?,
            _ => {
                return Err(r.error_at(line, format!("unknown command '{}'", token.to_text())));
            }
        }
        Ok(())
    }

    /// `l` / `la` (its name already read): a point light, white unless a colour follows.
    fn light(&mut self, r: &mut Reader, name: Option<String>) -> Result<(), String> {
        let position = r.vec3("l")?;
        let color = if r.next_is_number() {
            r.colour("l")?
        } else {
            Vec3::ONE
        };
        self.lights.push(PointLight {
            position,
            color,
            name,
        });
        Ok(())
    }

    /// `f` or `fm`: the material state for the geometry that follows.
    fn set_material(&mut self, fm: Fm) {
        self.fm = Some(fm);
        self.materials.states_read += 1;
    }

    /// `c`: an open cone.
    fn cone(&mut self, r: &mut Reader) -> Result<(), String> {
        let base = r.vec3("c")?;
        let r0 = r.number("c")?;
        let apex = r.vec3("c")?;
        let r1 = r.number("c")?;
        let material = self.material(None);
        self.stats.cones += 1;
        self.stats.cone_triangles += self.add(material, shapes::cone(base, r0, apex, r1));
        Ok(())
    }

    /// `s`: a sphere.
    fn sphere(&mut self, r: &mut Reader) -> Result<(), String> {
        let centre = r.vec3("s")?;
        let radius = r.number("s")?;
        let material = self.material(None);
        self.stats.spheres += 1;
        self.stats.sphere_triangles += self.add(material, shapes::sphere(centre, radius));
        Ok(())
    }

    /// `p` (positions) or `pp` (positions and normals): a polygon, as a fan.
    fn polygon(&mut self, r: &mut Reader, cmd: &str) -> Result<(), String> {
        let n = r.count(cmd, MAX_ITEMS)?;
        let mut positions = Vec::with_capacity(n.min(1024));
        let mut normals = Vec::new();
        for _ in 0..n {
            positions.push(r.vec3(cmd)?);
            if cmd == "pp" {
                normals.push(r.vec3(cmd)?.try_normalize().unwrap_or(Vec3::Z));
            }
        }
        let normals = (cmd == "pp").then_some(normals);
        let material = self.material(None);
        self.stats.polygons += 1;
        self.stats.polygon_triangles += self.add(material, shapes::polygon(positions, normals));
        Ok(())
    }

    /// `tt` (positions and uvs) or `ttp` (with normals): one textured triangle.
    fn textured_triangle(&mut self, r: &mut Reader, cmd: &str, dir: &Path) -> Result<(), String> {
        let (name, name_line) = r.name(cmd)?;
        let texture = self.texture(r, &name, name_line, dir)?;
        let mut g = Geometry {
            normals: (cmd == "ttp").then(Vec::new),
            indices: vec![0, 1, 2],
            ..Default::default()
        };
        let mut uvs = Vec::with_capacity(3);
        for _ in 0..3 {
            g.positions.push(r.vec3(cmd)?);
            if let Some(n) = g.normals.as_mut() {
                n.push(r.vec3(cmd)?.try_normalize().unwrap_or(Vec3::Z));
            }
            let uv: Vec2 = r.vec2(cmd)?;
            uvs.push(uv);
        }
        g.uvs = Some(uvs);
        let material = self.material(Some(texture));
        self.stats.textured_triangles += self.add(material, g);
        Ok(())
    }

    /// `m`: an indexed mesh, textured when it names a texture.
    fn mesh(&mut self, r: &mut Reader, dir: &Path) -> Result<(), String> {
        let mesh = read_mesh(r)?;
        let texture = match &mesh.texture {
            Some((name, name_line)) => Some(self.texture(r, name, *name_line, dir)?),
            None => None,
        };
        let material = self.material(texture);
        self.stats.meshes += 1;
        self.stats.mesh_triangles += self.add(material, mesh.geometry);
        Ok(())
    }

    /// `i detail name`: parses the named file in place when its detail is at most the
    /// current `d`.
    fn include(&mut self, r: &mut Reader, dir: &Path) -> Result<(), String> {
        let detail = r.int("i")?;
        let (name, name_line) = r.name("i")?;
        if detail > self.detail {
            return Ok(());
        }
        let candidates = include_candidates(dir, &self.main_dir, &name);
        let Some(path) = candidates.iter().find(|p| self.files.exists(p)) else {
            let looked: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
            return Err(r.error_at(
                name_line,
                format!(
                    "cannot find include '{name}' (looked in {})",
                    looked.join(", ")
                ),
            ));
        };
        let path = path.clone();
        // Errors inside the include carry their own file:line; a cycle is reported at the
        // `i` that closes it.
        self.builder.close_morph_group();
        match self.parse_file(&path, &name) {
            Err(e) if e.starts_with("include cycle") => {
                return Err(r.error_at(name_line, e));
            }
            other => other?,
        }
        self.builder.close_morph_group();
        Ok(())
    }

    /// `xs scale axis degrees translation {`: opens a static transform block.
    fn static_transform(&mut self, r: &mut Reader) -> Result<(), String> {
        let scale = r.vec3("xs")?;
        let axis = r.vec3("xs")?;
        let degrees = r.number("xs")?;
        let translation = r.vec3("xs")?;
        r.expect("{", "xs")?;
        let rotation = match axis.try_normalize() {
            Some(a) => Quat::from_axis_angle(a, degrees.to_radians()),
            None => Quat::IDENTITY,
        };
        let trs = Trs {
            translation,
            rotation,
            scale,
        };
        let node = self.builder.add_node(Some(self.scope()), "xs".into(), trs);
        self.scopes.push(node);
        self.stats.static_transforms += 1;
        Ok(())
    }

    /// `x name {`: opens a transform block driven by the `k name` block (resolved after the
    /// parse).
    fn animated_transform(&mut self, r: &mut Reader) -> Result<(), String> {
        let (name, _) = r.name("x")?;
        r.expect("{", "x")?;
        let node = self
            .builder
            .add_node(Some(self.scope()), name.clone(), Trs::default());
        self.scopes.push(node);
        self.x_nodes.push((node, name));
        self.stats.animated_transforms += 1;
        Ok(())
    }

    fn view(&mut self, r: &mut Reader) -> Result<(), String> {
        let mut view = View::default();
        let mut seen = 0;
        loop {
            let Some(t) = r.peek() else { break };
            match t.text {
                b"from" => {
                    view.from = {
                        r.next();
                        r.vec3("from")?
                    }
                }
                b"at" => {
                    view.at = {
                        r.next();
                        r.vec3("at")?
                    }
                }
                b"up" => {
                    view.up = {
                        r.next();
                        r.vec3("up")?
                    }
                }
                b"angle" => {
                    view.angle = {
                        r.next();
                        r.number("angle")?
                    }
                }
                b"hither" => {
                    view.hither = {
                        r.next();
                        r.number("hither")?
                    }
                }
                b"resolution" => {
                    r.next();
                    let w = r.count("resolution", u32::MAX as usize)? as u32;
                    let h = r.count("resolution", u32::MAX as usize)? as u32;
                    view.resolution = (w, h);
                }
                _ => break,
            }
            seen += 1;
        }
        if seen == 0 {
            let line = r.peek().map_or(r.lexer.line(), |t| t.line);
            return Err(r.error_at(
                line,
                "expected 'from', 'at', 'up', 'angle', 'hither' or 'resolution' after 'v'",
            ));
        }
        if view.hither < 1e-4 {
            view.hither = 1.0;
        }
        self.view = Some(view);
        Ok(())
    }

    fn tpa(&mut self, r: &mut Reader, line: u32) -> Result<(), String> {
        let k = r.count("tpa", MAX_MORPH_SAMPLES)?;
        if k == 0 {
            return Err(r.error_at(line, "'tpa' needs at least one sample"));
        }
        let mut tri = MorphTriangle {
            times: Vec::with_capacity(k.min(1024)),
            samples: Vec::with_capacity(k.min(1024)),
        };
        for _ in 0..k {
            tri.times.push(r.number("tpa")?);
            let mut s = [(Vec3::ZERO, Vec3::ZERO); 3];
            for v in &mut s {
                *v = (r.vec3("tpa")?, r.vec3("tpa")?);
            }
            tri.samples.push(s);
        }
        check_times(r, line, "tpa", tri.times.iter().copied())?;
        let material = self.material(None);
        let parent = self.scope();
        self.builder.add_morph_triangle(parent, material, tri);
        self.stats.morph_triangles += 1;
        Ok(())
    }

    /// Counts a track whose key times go back somewhere (Robots' `gun_rot` tracks restart
    /// at 42 after 48): the tracks evaluate them as the reference does (see
    /// `tracks::segment_uses`), and a note reports them.
    fn count_time_order(&mut self, mut times: impl Iterator<Item = f32>) {
        let Some(mut last) = times.next() else { return };
        for t in times {
            if t < last {
                self.tracks_going_back += 1;
                return;
            }
            last = t;
        }
    }

    fn key_block(&mut self, r: &mut Reader) -> Result<(), String> {
        let (name, _) = r.name("k")?;
        r.expect("{", "k")?;
        let mut block = KeyBlock::default();
        loop {
            let t = r.token("a motion or '}'", "k")?;
            let line = t.line;
            match t.text {
                b"}" => break,
                b"transl" | b"scale" => {
                    let motion = if t.text == b"transl" {
                        "transl"
                    } else {
                        "scale"
                    };
                    let n = r.count(motion, MAX_ITEMS)?;
                    if n < 4 {
                        return Err(r.error_at(
                            line,
                            format!("'{motion}' needs at least 4 keys, found {n}"),
                        ));
                    }
                    let keys = (0..n)
                        .map(|_| {
                            Ok(PositionKey {
                                time: r.number(motion)?,
                                value: r.vec3(motion)?,
                                tcb: tcb(r, motion)?,
                            })
                        })
                        .collect::<Result<Vec<_>, String>>()?;
                    self.count_time_order(keys.iter().map(|k| k.time));
                    if motion == "transl" {
                        block.translation = Some(keys);
                    } else {
                        block.scale = Some(keys);
                    }
                }
                b"rot" => {
                    let n = r.count("rot", MAX_ITEMS)?;
                    if n < 4 {
                        return Err(
                            r.error_at(line, format!("'rot' needs at least 4 keys, found {n}"))
                        );
                    }
                    let keys = (0..n)
                        .map(|_| {
                            Ok(RotationKey {
                                time: r.number("rot")?,
                                axis: r.vec3("rot")?,
                                angle_deg: r.number("rot")?,
                                tcb: tcb(r, "rot")?,
                            })
                        })
                        .collect::<Result<Vec<_>, String>>()?;
                    self.count_time_order(keys.iter().map(|k| k.time));
                    block.rotation = Some(keys);
                }
                b"visibility" => {
                    let n = r.count("visibility", MAX_ITEMS)?;
                    let keys = (0..n)
                        .map(|_| {
                            Ok(VisibilityKey {
                                time: r.number("visibility")?,
                                visible: r.number("visibility")? != 0.0,
                            })
                        })
                        .collect::<Result<Vec<_>, String>>()?;
                    self.count_time_order(keys.iter().map(|k| k.time));
                    block.visibility = Some(keys);
                }
                _ => {
                    return Err(r.error_at(
                        line,
                        format!(
                            "expected 'transl', 'rot', 'scale', 'visibility' or '}}' in 'k {name}', found '{}'",
                            t.to_text()
                        ),
                    ));
                }
            }
        }
        self.key_blocks.insert(name, block);
        Ok(())
    }
}
