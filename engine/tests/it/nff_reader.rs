//! The NFF reader: the quirks of real files, and a clear file:line error for
//! every kind of bad input.

use crate::common;

use sray_engine::Error;
use sray_engine::nff::{MAX_LINE_BYTES, read_nff, read_nff_from};
use sray_engine::progress::NoProgress;
use sray_engine::scene::recorder::{Event, Recorder};
use sray_engine::shapes::{Cone, Shape, Sphere};
use std::path::Path;

const VIEW: &str = "v\nfrom 0 0 5\nat 0 0 0\nup 0 1 0\nangle 45\nhither 1\nresolution 64 64\n";

fn parse(text: &str) -> Result<Recorder, Error> {
    let mut r = Recorder::default();
    read_nff_from(text.as_bytes(), Path::new("test.nff"), &mut r, &NoProgress)?;
    Ok(r)
}

/// The error for `text`, which must name test.nff and `line`.
fn error_at(text: &str, line: u64) -> String {
    match parse(text) {
        Ok(_) => panic!("accepted bad input:\n{text}"),
        Err(Error::Nff {
            file,
            line: l,
            message,
        }) => {
            assert_eq!(file, Path::new("test.nff"));
            assert_eq!(l, line, "wrong line for: {message}\n{text}");
            message
        }
        Err(e) => panic!("wrong error kind: {e}"),
    }
}

#[test]
fn reads_all_seven_shared_files() {
    for (name, size) in common::DEFAULT_SCENES {
        let mut r = Recorder::default();
        read_nff(
            &common::spd_fixtures().join(format!("{name}{size}.nff")),
            &mut r,
            &NoProgress,
        )
        .unwrap();
        assert!(r.objects().count() > 4000, "{name}");
    }
}

#[test]
fn cone_on_one_line_and_on_three() {
    let one = parse(&format!("{VIEW}c 0 0 0 1 0 0 2 0.5\n")).unwrap();
    let three = parse(&format!("{VIEW}c\n0 0 0 1\n0 0 2 0.5\n")).unwrap();
    assert_eq!(one.events, three.events);
    assert!(matches!(
        one.objects().next().unwrap().shape(),
        Shape::Cone(Cone { apex_radius, .. }) if apex_radius == 0.5
    ));
}

#[test]
fn printf_g_numbers_comments_blank_lines_and_crlf() {
    let text = format!(
        "# a comment\r\n\r\nb 0.078 0.361 0.753\r\n{VIEW}\n  # indented comment\nl 1e+01 -0 2.5e-05\nf 1 1 1 1 0 100000 0 1\ns -0 1e-05 3 0.5\n"
    );
    let r = parse(&text).unwrap();
    assert!(r.events.contains(&Event::Background([0.078, 0.361, 0.753])));
    let s = r.objects().next().unwrap();
    assert_eq!(
        s.shape(),
        Shape::Sphere(Sphere {
            center: [-0.0, 1e-5, 3.0],
            radius: 0.5
        })
    );
    // -0 keeps its sign.
    assert_eq!(s.numbers()[0].to_bits(), (-0.0f32).to_bits());
    let light = r.events.iter().find_map(|e| match e {
        Event::Light(l) => Some(*l),
        _ => None,
    });
    assert_eq!(light.unwrap().position, [10.0, -0.0, 2.5e-5]);
    assert_eq!(light.unwrap().color, None);
}

#[test]
fn light_with_colour_and_patches() {
    let r = parse(&format!(
        "{VIEW}l 1 2 3 0.5 0.25 1\npp 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n"
    ))
    .unwrap();
    assert!(
        r.events
            .iter()
            .any(|e| matches!(e, Event::Light(l) if l.color == Some([0.5, 0.25, 1.0])))
    );
    assert!(matches!(
        r.objects().next().unwrap().shape(),
        Shape::Patch(_)
    ));
}

#[test]
fn view_lines_may_come_in_any_order_and_omit_hither_and_resolution() {
    let r = parse("v\nangle 30\nup 0 0 1\nat 0 0 0\nfrom 1 2 3\ns 0 0 0 1\n").unwrap();
    let v = r.events.iter().find_map(|e| match e {
        Event::View(v) => Some(*v),
        _ => None,
    });
    let v = v.unwrap();
    assert_eq!(v.from, [1.0, 2.0, 3.0]);
    assert_eq!(v.resolution, [512, 512]);
    assert_eq!(r.objects().count(), 1);
}

#[test]
fn unknown_entity() {
    let m = error_at(&format!("{VIEW}s 0 0 0 1\nq 1 2 3\n"), 9);
    assert!(m.contains("unknown entity 'q'"), "{m}");
}

#[test]
fn too_few_and_too_many_numbers() {
    let m = error_at(&format!("{VIEW}s 0 0 1\n"), 8);
    assert!(m.contains("needs 4 numbers, found 3"), "{m}");
    let m = error_at(&format!("{VIEW}s 0 0 1 2 3\n"), 8);
    assert!(m.contains("takes 4 numbers"), "{m}");
    let m = error_at(&format!("{VIEW}f 1 1 1 1 0\n"), 8);
    assert!(m.contains("needs 8 numbers"), "{m}");
    let m = error_at(&format!("{VIEW}p 3\n0 0 0\n1 0\n0 1 0\n"), 10);
    assert!(m.contains("needs 3 numbers, found 2"), "{m}");
    let m = error_at(&format!("{VIEW}l 1 2 3 4\n"), 8);
    assert!(m.contains("3 numbers (or 6"), "{m}");
    let m = error_at("b 1 1\n", 1);
    assert!(m.contains("needs 3 numbers"), "{m}");
}

#[test]
fn non_numeric_and_non_finite_numbers() {
    let m = error_at(&format!("{VIEW}s 0 zero 0 1\n"), 8);
    assert!(m.contains("'zero' is not a number"), "{m}");
    for bad in ["nan", "NaN", "inf", "-infinity", "1e999"] {
        let m = error_at(&format!("{VIEW}s 0 {bad} 0 1\n"), 8);
        assert!(
            m.contains("not a finite number") || m.contains("too large"),
            "{bad}: {m}"
        );
    }
    let m = error_at(&format!("{VIEW}s 0 1e39 0 1\n"), 8);
    assert!(m.contains("too large for single precision"), "{m}");
}

#[test]
fn polygon_vertex_counts() {
    let m = error_at(&format!("{VIEW}p 2\n0 0 0\n1 0 0\n"), 8);
    assert!(m.contains("at least 3"), "{m}");
    let m = error_at(&format!("{VIEW}p 4000000000\n0 0 0\n"), 8);
    assert!(m.contains("more than the limit"), "{m}");
    let m = error_at(&format!("{VIEW}p 99999999999999999999999\n"), 8);
    assert!(m.contains("not a whole number"), "{m}");
    let m = error_at(&format!("{VIEW}p -3\n"), 8);
    assert!(m.contains("not a whole number"), "{m}");
    let m = error_at(&format!("{VIEW}pp 3.5\n"), 8);
    assert!(m.contains("not a whole number"), "{m}");
}

#[test]
fn objects_before_the_view() {
    let m = error_at("b 0 0 0\ns 0 0 0 1\n", 2);
    assert!(m.contains("before the view"), "{m}");
    let m = error_at("p 3\n0 0 0\n1 0 0\n0 1 0\n", 1);
    assert!(m.contains("before the view"), "{m}");
}

#[test]
fn truncated_files() {
    let m = error_at(&format!("{VIEW}p 5\n0 0 0\n1 0 0\n"), 10);
    assert!(
        m.contains("file ends inside the polygon") && m.contains("2 of 5"),
        "{m}"
    );
    let m = error_at(&format!("{VIEW}c\n0 0 0 1\n"), 9);
    assert!(m.contains("file ends inside the cone"), "{m}");
    let m = error_at("v\nfrom 0 0 1\nat 0 0 0\n", 1);
    assert!(m.contains("no 'up' line"), "{m}");
}

#[test]
fn negative_radius_and_bad_view() {
    let m = error_at(&format!("{VIEW}s 0 0 0 -1\n"), 8);
    assert!(m.contains("negative"), "{m}");
    let m = error_at("v\nfrom 0 0 1\nat 0 0 0\nup 0 1 0\nangle 0\n", 1);
    assert!(m.contains("angle"), "{m}");
    let m = error_at(
        "v\nfrom 0 0 1\nat 0 0 0\nup 0 1 0\nangle 40\nresolution 0 10\n",
        6,
    );
    assert!(m.contains("resolution"), "{m}");
    let m = error_at(&format!("{VIEW}{VIEW}"), 8);
    assert!(m.contains("second view"), "{m}");
}

#[test]
fn overlong_lines_and_binary_junk() {
    let long = format!("{VIEW}s 0 0 0 {}\n", "1".repeat(MAX_LINE_BYTES + 10));
    let m = error_at(&long, 8);
    assert!(m.contains("longer than"), "{m}");
    let mut bytes = VIEW.as_bytes().to_vec();
    bytes.extend_from_slice(b"s 0 0 \xff\xfe 1\n");
    let mut r = Recorder::default();
    let e = read_nff_from(&bytes[..], Path::new("test.nff"), &mut r, &NoProgress).unwrap_err();
    assert!(
        e.to_string()
            .contains("test.nff:8: line is not valid UTF-8"),
        "{e}"
    );
}

#[test]
fn an_empty_scene_is_fine() {
    let r = parse(VIEW).unwrap();
    assert_eq!(r.objects().count(), 0);
}

#[test]
fn missing_file_names_the_path() {
    let mut r = Recorder::default();
    let e = read_nff(Path::new("/nonexistent/x.nff"), &mut r, &NoProgress).unwrap_err();
    assert!(e.to_string().starts_with("/nonexistent/x.nff: "), "{e}");
}
