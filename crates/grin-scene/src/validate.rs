//! Semantic checks on a parsed [`Scene`]: values that are well-formed TOML but unusable
//! (negative radii, n <= 0, empty render sizes...). Each problem is reported with the
//! dotted key path of the offending value; the loader turns that into file:line:column.
//!
//! Over 600 lines: one concept, every semantic check of a scene, table by table.

use crate::{
    AmbientIndex, BoundsSpec, Camera, FieldSpec, Light, Material, MediumSpec, NoiseSpec, Object,
    RenderSettings, Scene, Shape, Sky, StepSpec, VdbMap, VdbSpec,
};

/// Largest image side accepted (16K): bigger is almost certainly a typo, and the frame
/// buffers of a 16384^2 image already take ~4 GB.
pub const MAX_IMAGE_SIDE: u32 = 16_384;
/// Largest world coordinate or size accepted (world units). Earth's radius in metres
/// (6.4e6) fits; beyond, the GPU's f32 positions resolve less than one world unit, and a
/// medium at 1e300 made the bake's grid arithmetic overflow and spin.
pub const MAX_WORLD_COORDINATE: f64 = 1e7;
/// Smallest world size accepted (world units): a radius, or a box's extent along an axis.
/// A nanometre in metres; a sphere of radius 1e-300 squared its radius to 0 and missed
/// the ray aimed at its centre.
pub const MIN_WORLD_SIZE: f64 = 1e-9;
/// Largest refractive index accepted, of a field anywhere inside its medium or of the
/// ambient: well above any material's (germanium ~4, the highest metamaterials ~40); at
/// 1e300 the path's n^2 overflowed and every ray ended with a NaN optical path.
pub const MAX_INDEX: f64 = 1e3;
/// Largest `render.max_steps` accepted: the GPU bounds its march loop by 2 * max_steps + 2
/// in u32 arithmetic, which 2^31 would overflow (every medium pixel then stopped at once).
pub const MAX_STEPS: u32 = 1 << 30;
/// The fastest lens: f/0.5 is the limit of an aplanatic lens in air (n sin(theta) <= 1).
pub const MIN_F_NUMBER: f64 = 0.5;
/// Wavelengths an interferogram accepts, in nm.
pub const MIN_WAVELENGTH_NM: f64 = 10.0;
pub const MAX_WAVELENGTH_NM: f64 = 1e6;
/// Most objects accepted: both backends test every object on every ray (no acceleration
/// structure), and on the GPU tens of thousands of objects ended every medium pixel in
/// `error`. A thousand keeps a frame interactive on lavapipe.
pub const MAX_OBJECTS: usize = 1024;
/// Most pilot rays accepted (`render.pilot_rays`): a few hundred already resolve any
/// view the pilots can; millions would trace a frame's worth before the frame.
pub const MAX_PILOT_RAYS: u32 = 4096;
/// Noise octaves accepted: beyond 16 the octaves are finer than f64 noise lattices resolve.
pub const MAX_NOISE_OCTAVES: u32 = 16;

/// A validation failure: the key path and what is wrong with its value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Problem {
    pub key: String,
    pub message: String,
}

type Check = Result<(), Problem>;

fn fail(key: impl Into<String>, message: impl Into<String>) -> Check {
    Err(Problem {
        key: key.into(),
        message: message.into(),
    })
}

fn finite(key: &str, v: f64) -> Check {
    if v.is_finite() {
        Ok(())
    } else {
        fail(key, format!("must be finite, got {v}"))
    }
}

fn positive(key: &str, v: f64) -> Check {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        fail(key, format!("must be > 0, got {v}"))
    }
}

fn non_negative(key: &str, v: f64) -> Check {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        fail(key, format!("must be >= 0, got {v}"))
    }
}

fn finite3(key: &str, v: [f64; 3]) -> Check {
    if !v.iter().all(|c| c.is_finite()) {
        return fail(key, format!("all components must be finite, got {v:?}"));
    }
    if v.iter().any(|c| c.abs() > MAX_WORLD_COORDINATE) {
        return fail(
            key,
            format!("components must lie within ±{MAX_WORLD_COORDINATE:e} world units, got {v:?}"),
        );
    }
    Ok(())
}

/// The medium's radius: a [`size`] of at least [`MIN_WORLD_SIZE`].
fn medium_size(key: &str, v: f64) -> Check {
    size(key, v)?;
    if v < MIN_WORLD_SIZE {
        return fail(
            key,
            format!("must be at least {MIN_WORLD_SIZE:e} world units, got {v:e}"),
        );
    }
    Ok(())
}

/// A radius or other world size: positive, finite, at most [`MAX_WORLD_COORDINATE`].
fn size(key: &str, v: f64) -> Check {
    positive(key, v)?;
    if v > MAX_WORLD_COORDINATE {
        return fail(
            key,
            format!("must be at most {MAX_WORLD_COORDINATE:e} world units, got {v:?}"),
        );
    }
    Ok(())
}

fn nonzero3(key: &str, v: [f64; 3]) -> Check {
    finite3(key, v)?;
    if v.iter().any(|c| *c != 0.0) {
        Ok(())
    } else {
        fail(key, "must be a non-zero vector")
    }
}

fn colour(key: &str, v: [f64; 3]) -> Check {
    if v.iter().all(|c| c.is_finite() && *c >= 0.0) {
        Ok(())
    } else {
        fail(
            key,
            format!("colour components must be finite and >= 0, got {v:?}"),
        )
    }
}

fn min_max(key: &str, min: [f64; 3], max: [f64; 3]) -> Check {
    finite3(&format!("{key}.min"), min)?;
    finite3(&format!("{key}.max"), max)?;
    if !(0..3).all(|i| min[i] < max[i]) {
        return fail(
            format!("{key}.max"),
            format!("must be > min in every component, got min {min:?}, max {max:?}"),
        );
    }
    if (0..3).any(|i| max[i] - min[i] < MIN_WORLD_SIZE) {
        return fail(
            format!("{key}.max"),
            format!(
                "must be at least {MIN_WORLD_SIZE:e} world units beyond min in every component, got min {min:?}, max {max:?}"
            ),
        );
    }
    Ok(())
}

/// A refractive index: finite, > 0 and at most [`MAX_INDEX`].
fn index(key: &str, v: f64) -> Check {
    positive(key, v)?;
    if v > MAX_INDEX {
        return fail(key, format!("must be at most {MAX_INDEX:e}, got {v:e}"));
    }
    Ok(())
}

fn non_empty(key: &str, s: &str) -> Check {
    if s.trim().is_empty() {
        fail(key, "must not be empty")
    } else {
        Ok(())
    }
}

/// Check the whole scene; the first problem found.
pub(crate) fn validate(scene: &Scene) -> Check {
    camera(&scene.camera)?;
    if scene.objects.len() > MAX_OBJECTS {
        return fail(
            format!("object[{MAX_OBJECTS}]"),
            format!(
                "the scene has {} objects; at most {MAX_OBJECTS} are supported (every ray \
                 tests every object)",
                scene.objects.len()
            ),
        );
    }
    for (i, o) in scene.objects.iter().enumerate() {
        object(&format!("object[{i}]"), o)?;
    }
    if let Some(m) = &scene.medium {
        medium(m)?;
    }
    for (i, l) in scene.lights.iter().enumerate() {
        light(&format!("light[{i}]"), l)?;
    }
    sky(&scene.sky)?;
    if let Some(s) = &scene.sensor {
        sensor(s)?;
    }
    if let Some(a) = &scene.animation {
        positive("animation.fps", a.fps)?;
        let [first, last] = a.frames;
        if last < first {
            return fail(
                "animation.frames",
                format!("[{first}, {last}] ends before it starts"),
            );
        }
        if crate::frames::frame_count(first, last) > crate::frames::MAX_FRAMES as u64 {
            return fail(
                "animation.frames",
                format!(
                    "[{first}, {last}] has more than {} frames",
                    crate::frames::MAX_FRAMES
                ),
            );
        }
    }
    if let Some(o) = &scene.optics {
        optics(o, scene.medium.is_some())?;
    }
    render(&scene.render)
}

fn optics(o: &crate::OpticsSpec, has_medium: bool) -> Check {
    use crate::OpticsMode;
    if !has_medium {
        return fail(
            "optics",
            "an optical output needs a [medium] to look through",
        );
    }
    if let Some(a) = o.accuracy {
        positive("optics.accuracy", a)?;
        if o.accuracy_unit() == crate::AccuracyUnit::Radians && a >= 1.0 {
            return fail(
                "optics.accuracy",
                format!(
                    "schlieren's is an exit-direction error in radians, below 1 (pixels and \
                     waves are for the other outputs), got {a}"
                ),
            );
        }
    }
    if let Some(p) = &o.plane {
        finite3("optics.plane.point", p.point)?;
        nonzero3("optics.plane.normal", p.normal)?;
    } else if o.mode == OpticsMode::Bos {
        return fail(
            "optics.plane",
            "BOS needs the plane of its dot background: plane = { point = [..], normal = [..] }",
        );
    }
    finite("optics.knife.angle_deg", o.knife.angle_deg)?;
    if !(o.knife.cutoff > 0.0 && o.knife.cutoff < 1.0) {
        return fail(
            "optics.knife.cutoff",
            format!(
                "must be in (0, 1) (the fraction of the source blocked), got {}",
                o.knife.cutoff
            ),
        );
    }
    positive("optics.knife.source_size_rad", o.knife.source_size_rad)?;
    positive("optics.wavelength_nm", o.wavelength_nm)?;
    if !(MIN_WAVELENGTH_NM..=MAX_WAVELENGTH_NM).contains(&o.wavelength_nm) {
        // The phase is 2 pi OPD / wavelength: 1e-300 nm made it infinite.
        return fail(
            "optics.wavelength_nm",
            format!(
                "must be in {MIN_WAVELENGTH_NM}..={MAX_WAVELENGTH_NM:e} nm (extreme ultraviolet \
                 to millimetre waves; the phase is 2 pi OPD / wavelength), got {:?}",
                o.wavelength_nm
            ),
        );
    }
    non_negative("optics.fringes.spacing_px", o.fringes.spacing_px)?;
    finite("optics.fringes.angle_deg", o.fringes.angle_deg)?;
    size("optics.dots.diameter", o.dots.diameter)?;
    dot_density("optics.dots.density", o.dots.density)?;
    finite("optics.screen.distance", o.screen.distance)?;
    if let Some([w, h]) = o.screen.size {
        size("optics.screen.size", w)?;
        size("optics.screen.size", h)?;
    }
    if !(1..=1024).contains(&o.screen.rays_per_pixel) {
        return fail(
            "optics.screen.rays_per_pixel",
            format!("must be in 1..=1024, got {}", o.screen.rays_per_pixel),
        );
    }
    Ok(())
}

fn camera(c: &Camera) -> Check {
    finite3("camera.position", c.position)?;
    finite3("camera.look_at", c.look_at)?;
    nonzero3("camera.up", c.up)?;
    if c.position == c.look_at {
        return fail(
            "camera.look_at",
            format!(
                "must differ from camera.position, both are {:?}",
                c.position
            ),
        );
    }
    let v: Vec<f64> = (0..3).map(|i| c.look_at[i] - c.position[i]).collect();
    let cross = [
        v[1] * c.up[2] - v[2] * c.up[1],
        v[2] * c.up[0] - v[0] * c.up[2],
        v[0] * c.up[1] - v[1] * c.up[0],
    ];
    let norm = |a: &[f64]| a.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm(&cross) <= 1e-9 * norm(&v) * norm(&c.up) {
        return fail(
            "camera.up",
            format!("must not be parallel to the view direction, got {:?}", c.up),
        );
    }
    if !(c.fov_y_deg.is_finite() && c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0) {
        return fail(
            "camera.fov_y_deg",
            format!("must be in (0, 180) degrees, got {}", c.fov_y_deg),
        );
    }
    lens(c)
}

fn lens(c: &Camera) -> Check {
    let given = |v: Option<f64>, key: &str| v.map_or(Ok(()), |v| size(key, v));
    given(c.focal_length_mm, "camera.focal_length_mm")?;
    given(c.sensor_height_mm, "camera.sensor_height_mm")?;
    given(c.pixel_pitch_um, "camera.pixel_pitch_um")?;
    given(c.f_number, "camera.f_number")?;
    given(c.focus_distance, "camera.focus_distance")?;
    match (c.focal_length_mm, c.sensor_height_mm, c.pixel_pitch_um) {
        (Some(_), None, None) => fail(
            "camera.focal_length_mm",
            "needs the sensor: sensor_height_mm, or pixel_pitch_um (times [render] height)",
        ),
        (Some(_), Some(_), Some(_)) => fail(
            "camera.pixel_pitch_um",
            "give sensor_height_mm or pixel_pitch_um, not both",
        ),
        (None, Some(_), _) | (None, _, Some(_)) => fail(
            if c.sensor_height_mm.is_some() {
                "camera.sensor_height_mm"
            } else {
                "camera.pixel_pitch_um"
            },
            "describes the sensor for focal_length_mm, which is missing",
        ),
        _ => Ok(()),
    }?;
    if c.f_number.is_some() && c.focal_length_mm.is_none() {
        return fail(
            "camera.f_number",
            "needs focal_length_mm (the aperture is focal length / f-number)",
        );
    }
    if let Some(n) = c.f_number
        && n < MIN_F_NUMBER
    {
        // Also what keeps the aperture (focal length / f-number) within the coordinates
        // the GPU resolves: f_number 1e-300 made an aperture of 5e298 m.
        return fail(
            "camera.f_number",
            format!(
                "must be at least {MIN_F_NUMBER} (the fastest a lens in air can be, \
                 n sin(theta) <= 1), got {n:?}"
            ),
        );
    }
    if c.focus_distance.is_some() && c.f_number.is_none() {
        return fail(
            "camera.focus_distance",
            "only matters with an aperture: set f_number",
        );
    }
    Ok(())
}

fn sensor(s: &crate::Sensor) -> Check {
    non_negative("sensor.full_well", s.full_well)?;
    non_negative("sensor.read_noise", s.read_noise)?;
    if s.read_noise > 0.0 && s.full_well == 0.0 {
        return fail(
            "sensor.read_noise",
            "is in electrons: set full_well (electrons at a value of 1) too",
        );
    }
    if s.bits > 24 {
        return fail(
            "sensor.bits",
            format!("must be at most 24 (0: no quantisation), got {}", s.bits),
        );
    }
    Ok(())
}

fn object(key: &str, o: &Object) -> Check {
    match &o.shape {
        Shape::Sphere { center, radius } => {
            finite3(&format!("{key}.shape.sphere.center"), *center)?;
            size(&format!("{key}.shape.sphere.radius"), *radius)?;
        }
        Shape::Plane { point, normal } => {
            finite3(&format!("{key}.shape.plane.point"), *point)?;
            nonzero3(&format!("{key}.shape.plane.normal"), *normal)?;
        }
        Shape::Box { min, max } => min_max(&format!("{key}.shape.box"), *min, *max)?,
    }
    material(&format!("{key}.material"), &o.material)?;
    surface_placement(key, o)
}

/// Where an image or dot pattern lies: on planes and boxes only; an image on a plane
/// needs its size, on a box it spans each face.
fn surface_placement(key: &str, o: &Object) -> Check {
    let (name, size, center) = match &o.material {
        Material::Texture { size, center, .. } => ("texture", *size, *center),
        Material::Dots { center, .. } => ("dots", None, *center),
        _ => return Ok(()),
    };
    let m = format!("{key}.material.{name}");
    match o.shape {
        Shape::Sphere { .. } => fail(
            m,
            format!("`{name}` maps onto planes and boxes; this object is a sphere"),
        ),
        Shape::Plane { .. } if name == "texture" && size.is_none() => fail(
            format!("{m}.size"),
            "an image on a plane needs its size in world units: size = [width, height]",
        ),
        Shape::Box { .. } if size.is_some() || center.is_some() => fail(
            m,
            "on a box the image or pattern is placed on each face; `size` and `center` are \
             for planes",
        ),
        _ => Ok(()),
    }
}

fn material(key: &str, m: &Material) -> Check {
    match m {
        Material::Diffuse { color } => colour(&format!("{key}.diffuse.color"), *color),
        Material::Checker {
            color_a,
            color_b,
            scale,
        } => {
            colour(&format!("{key}.checker.color_a"), *color_a)?;
            colour(&format!("{key}.checker.color_b"), *color_b)?;
            positive(&format!("{key}.checker.scale"), *scale)
        }
        Material::Mirror { color } => colour(&format!("{key}.mirror.color"), *color),
        Material::Metal { color } => colour(&format!("{key}.metal.color"), *color),
        Material::Glass { ior, color } => {
            positive(&format!("{key}.glass.ior"), *ior)?;
            colour(&format!("{key}.glass.color"), *color)
        }
        Material::Texture {
            path,
            size: image_size,
            center,
            border,
            color,
            ..
        } => {
            let k = |p: &str| format!("{key}.texture.{p}");
            non_empty(&k("path"), path)?;
            if let Some([w, h]) = image_size {
                size(&k("size"), *w)?;
                size(&k("size"), *h)?;
            }
            if let Some(c) = center {
                finite3(&k("center"), *c)?;
            }
            colour(&k("border"), *border)?;
            colour(&k("color"), *color)
        }
        Material::Dots {
            diameter,
            density,
            color,
            background,
            center,
            ..
        } => {
            let k = |p: &str| format!("{key}.dots.{p}");
            size(&k("diameter"), *diameter)?;
            dot_density(&k("density"), *density)?;
            if let Some(c) = center {
                finite3(&k("center"), *c)?;
            }
            colour(&k("color"), *color)?;
            colour(&k("background"), *background)
        }
    }
}

fn dot_density(key: &str, density: f64) -> Check {
    if density > 0.0 && density <= 1.0 {
        Ok(())
    } else {
        fail(
            key,
            format!("must be in (0, 1] (the fraction of the surface covered), got {density}"),
        )
    }
}

fn medium(m: &MediumSpec) -> Check {
    match m.bounds {
        BoundsSpec::Sphere { center, radius } => {
            finite3("medium.bounds.sphere.center", center)?;
            medium_size("medium.bounds.sphere.radius", radius)?;
        }
        BoundsSpec::Box { min, max } => min_max("medium.bounds.box", min, max)?,
    }
    match m.ambient_index {
        AmbientIndex::Value(v) => index("medium.ambient_index", v)?,
        AmbientIndex::Auto if !matches!(m.field, FieldSpec::Vdb(_)) => fail(
            "medium.ambient_index",
            "\"auto\" takes the index a VDB grid's background maps to; give a number for \
             this field",
        )?,
        AmbientIndex::Auto | AmbientIndex::Unset => {}
    }
    field(&m.field)
}

fn field(f: &FieldSpec) -> Check {
    const K: &str = "medium.field";
    let k = |p: &str| format!("{K}.{p}");
    match f {
        FieldSpec::Uniform { n } => index(&k("n"), *n),
        FieldSpec::LinearN2 { n0, k: slope, .. } => {
            index(&k("n0"), *n0)?;
            finite(&k("k"), *slope)
        }
        FieldSpec::GrinRod { n0, a, .. } => {
            index(&k("n0"), *n0)?;
            positive(&k("a"), *a)
        }
        FieldSpec::Luneburg { radius } => radius.map_or(Ok(()), |r| positive(&k("radius"), r)),
        FieldSpec::MaxwellFishEye { n0, a } => {
            index(&k("n0"), *n0)?;
            positive(&k("a"), *a)
        }
        FieldSpec::Eaton { radius, core } => {
            radius.map_or(Ok(()), |r| positive(&k("radius"), r))?;
            if core.is_finite() && *core > 0.0 && *core < 1.0 {
                Ok(())
            } else {
                fail(
                    k("core"),
                    format!("must be in (0, 1) (a fraction of the radius), got {core}"),
                )
            }
        }
        FieldSpec::ExponentialAtmosphere {
            e,
            scale_height,
            base,
            ..
        } => {
            finite(&k("e"), *e)?;
            positive(&k("scale_height"), *scale_height)?;
            finite(&k("base"), *base)
        }
        FieldSpec::Plume { plumes } => {
            if plumes.is_empty() {
                return fail(k("plumes"), "must list at least one plume");
            }
            for (i, p) in plumes.iter().enumerate() {
                finite(&k(&format!("plumes[{i}].a")), p.a)?;
                finite3(&k(&format!("plumes[{i}].center")), p.center)?;
                positive(&k(&format!("plumes[{i}].s")), p.s)?;
            }
            Ok(())
        }
        FieldSpec::Expr { n, t } => {
            non_empty(&k("n"), n)?;
            finite(&k("t"), *t)
        }
        FieldSpec::Noise(spec) => noise(spec),
        FieldSpec::Vdb(spec) => vdb(spec),
        FieldSpec::Baked { path, .. } => non_empty(&k("path"), path),
    }
}

fn noise(s: &NoiseSpec) -> Check {
    let k = |p: &str| format!("medium.field.{p}");
    if !(1..=MAX_NOISE_OCTAVES).contains(&s.octaves) {
        return fail(
            k("octaves"),
            format!("must be in 1..={MAX_NOISE_OCTAVES}, got {}", s.octaves),
        );
    }
    positive(&k("frequency"), s.frequency)?;
    finite(&k("amplitude"), s.amplitude)?;
    positive(&k("lacunarity"), s.lacunarity)?;
    positive(&k("persistence"), s.persistence)?;
    if !(s.envelope.is_finite() && (0.0..=1.0).contains(&s.envelope)) {
        return fail(
            k("envelope"),
            format!(
                "must be in [0, 1] (a fraction of the half-size), got {}",
                s.envelope
            ),
        );
    }
    finite3(&k("drift"), s.drift)?;
    finite(&k("t"), s.t)
}

fn vdb(s: &VdbSpec) -> Check {
    let k = |p: &str| format!("medium.field.{p}");
    non_empty(&k("path"), &s.path)?;
    non_empty(&k("grid"), &s.grid)?;
    positive(&k("units"), s.units)?;
    positive(&k("scale"), s.scale)?;
    finite3(&k("rotate_deg"), s.rotate_deg)?;
    finite3(&k("translate"), s.translate)?;
    match s.map {
        VdbMap::Index { .. } => Ok(()),
        VdbMap::Linear { k: slope } => finite(&k("map.linear.k"), slope),
        VdbMap::GladstoneDale {
            ambient_temperature_k,
            scale_k,
            pressure_pa,
            k_gd,
            r_specific,
        } => {
            positive(
                &k("map.gladstone-dale.ambient_temperature_k"),
                ambient_temperature_k,
            )?;
            finite(&k("map.gladstone-dale.scale_k"), scale_k)?;
            positive(&k("map.gladstone-dale.pressure_pa"), pressure_pa)?;
            positive(&k("map.gladstone-dale.k_gd"), k_gd)?;
            positive(&k("map.gladstone-dale.r_specific"), r_specific)
        }
    }
}

fn light(key: &str, l: &Light) -> Check {
    match l {
        Light::Point {
            position,
            intensity,
        } => {
            finite3(&format!("{key}.point.position"), *position)?;
            colour(&format!("{key}.point.intensity"), *intensity)
        }
        Light::Directional {
            direction,
            intensity,
        } => {
            nonzero3(&format!("{key}.directional.direction"), *direction)?;
            colour(&format!("{key}.directional.intensity"), *intensity)
        }
    }
}

fn sky(s: &Sky) -> Check {
    match s {
        Sky::Gradient {
            horizon,
            zenith,
            ground,
        } => {
            colour("sky.gradient.horizon", *horizon)?;
            colour("sky.gradient.zenith", *zenith)?;
            colour("sky.gradient.ground", *ground)
        }
        Sky::Map { path, intensity } => {
            non_empty("sky.map.path", path)?;
            non_negative("sky.map.intensity", *intensity)
        }
        Sky::Plate { path, intensity } => {
            non_empty("sky.plate.path", path)?;
            non_negative("sky.plate.intensity", *intensity)
        }
    }
}

fn render(r: &RenderSettings) -> Check {
    for (key, v) in [("render.width", r.width), ("render.height", r.height)] {
        if !(1..=MAX_IMAGE_SIDE).contains(&v) {
            return fail(key, format!("must be in 1..={MAX_IMAGE_SIDE}, got {v}"));
        }
    }
    if r.spp < 1 {
        return fail("render.spp", "must be >= 1, got 0");
    }
    if !(1..=MAX_STEPS).contains(&r.max_steps) {
        return fail(
            "render.max_steps",
            format!("must be in 1..={MAX_STEPS} (2^30), got {}", r.max_steps),
        );
    }
    if r.pilot_rays > MAX_PILOT_RAYS {
        return fail(
            "render.pilot_rays",
            format!(
                "must be in 0..={MAX_PILOT_RAYS} (0: no pilots), got {}",
                r.pilot_rays
            ),
        );
    }
    match r.step {
        StepSpec::Fixed(s) => positive("render.step.fixed", s),
        StepSpec::Heuristic {
            min,
            max,
            amplitude,
        } => {
            positive("render.step.heuristic.min", min)?;
            positive("render.step.heuristic.max", max)?;
            if min > max {
                return fail(
                    "render.step.heuristic.min",
                    format!("must be <= max ({max}), got {min}"),
                );
            }
            amplitude.map_or(Ok(()), |a| positive("render.step.heuristic.amplitude", a))
        }
        StepSpec::Adaptive { tolerance, initial } => {
            positive("render.step.adaptive.tolerance", tolerance)?;
            initial.map_or(Ok(()), |s| positive("render.step.adaptive.initial", s))
        }
        StepSpec::Auto(a) => {
            positive("render.step.auto", a)?;
            if a >= 1.0 {
                return fail(
                    "render.step.auto",
                    format!("is an exit-direction error in radians and must be < 1, got {a}"),
                );
            }
            Ok(())
        }
    }
}
