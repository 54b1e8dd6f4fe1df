use super::*;

#[test]
fn select_takes_a_whole_name_alone_else_every_name_containing_it() {
    let lens = luneburg(2).expect("lens");
    let lens_baked = baked(&lens, 16, Interp::Trilinear, Storage::F32).expect("baked lens");
    let all = || vec![lens.clone(), lens_baked.clone()];
    let names = |cases: Vec<Case>| cases.into_iter().map(|c| c.name).collect::<Vec<_>>();
    assert_eq!(
        names(select(all(), "luneburg").expect("a whole name")),
        ["luneburg"]
    );
    assert_eq!(
        names(select(all(), "baked").expect("part of a name")),
        ["luneburg-baked16-trilinear-f32"]
    );
    let err = select(all(), "nope")
        .expect_err("no case matches")
        .to_string();
    assert!(
        err.contains("--case nope") && err.contains("luneburg, luneburg-baked16"),
        "{err}"
    );
}
