use super::*;
use crate::gpu_data::tests::same_layout;
use crate::shaders::STAGES_WGSL;

/// Each stage's structs and their WGSL twins agree member by member (the padding
/// is WGSL's own, named only on the Rust side).
#[test]
fn stage_structs_match_their_wgsl_twins() {
    let w = STAGES_WGSL;
    same_layout!(w, SampleIn, r);
    same_layout!(w, SampleOut, grad_n, n, delta_n);
    same_layout!(w, IntegrateIn, r, h, t);
    same_layout!(
        w,
        IntegrateOut,
        r,
        evals,
        t,
        end_n,
        end_grad_n,
        err_r,
        err_t
    );
    same_layout!(w, TakeIn, r, ds_adapt, t);
    same_layout!(w, TakeOut, r, h, t, evals, ds_next);
    same_layout!(w, LeaveOut, r, h, t, evals, ds_next, outcome);
    same_layout!(w, RayIn, r, t);
    same_layout!(w, FlightOut, span, may_fly);
    same_layout!(w, SurfaceIn, r, n1, t, n2);
    same_layout!(
        w,
        SurfaceOut,
        dir,
        transmitted,
        normal,
        reflectance,
        s_in,
        s_out,
        signed_distance,
        met
    );
    same_layout!(w, SceneIn, r, t_min, t);
    same_layout!(w, SceneOut, normal, distance, sky, object);
    same_layout!(w, MarchControl, pending, round, budget);
    let (carry, _) = crate::gpu_data::tests::wgsl_offsets(w, "MarchCarryStored");
    assert_eq!(carry as u64, MARCH_CARRY_BYTES, "MarchCarryStored's size");
    same_layout!(
        w,
        MarchOut,
        point,
        opl,
        dir,
        length,
        evals,
        steps,
        transmittance,
        status,
        end
    );
}

/// The kernel declares one input and one output variable per stage at the same two
/// bindings; each stage's specialised module keeps only its own pair.
#[test]
fn each_specialised_stage_binds_only_its_own_structs() {
    fn io_of<S: Stage>() -> Vec<(u32, String)> {
        let module = specialize::specialise(specialize::Kernel::Stages, S::ENTRY_POINT, &[])
            .expect("the stage specialises and validates");
        let mut io: Vec<(u32, String)> = module
            .global_variables
            .iter()
            .filter_map(|(_, g)| {
                let b = g.binding.as_ref().filter(|b| b.group == 1)?;
                Some((b.binding, g.name.clone().unwrap_or_default()))
            })
            .collect();
        io.sort();
        io
    }
    let pair = |input: &str, output: &str| vec![(0, input.to_string()), (1, output.to_string())];
    assert_eq!(io_of::<Sample>(), pair("sample_in", "sample_out"));
    assert_eq!(io_of::<Integrate>(), pair("integrate_in", "integrate_out"));
    assert_eq!(io_of::<Take>(), pair("take_in", "take_out"));
    assert_eq!(io_of::<Leave>(), pair("take_in", "leave_out"));
    assert_eq!(io_of::<Flight>(), pair("ray_in", "flight_out"));
    assert_eq!(io_of::<Surface>(), pair("surface_in", "surface_out"));
    assert_eq!(io_of::<Scene>(), pair("scene_in", "scene_out"));
    let mut march = pair("ray_in", "march_out");
    march.extend([(2, "march_carry".into()), (3, "march_control".into())]);
    assert_eq!(io_of::<March>(), march);
}
