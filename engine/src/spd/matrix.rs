//! The SPD library's 4x4 matrices: row-major, row vectors on the left
//! (`v' = v M`). Every formula keeps the SPD's order of operations so that
//! generated coordinates match its output to the last printed digit.

pub type Mat4 = [[f64; 4]; 4];

/// The SPD's `PI`, 3.141592653589793, which is exactly this constant.
pub const PI: f64 = std::f64::consts::PI;

pub fn zero() -> Mat4 {
    [[0.0; 4]; 4]
}

pub fn identity() -> Mat4 {
    let mut m = zero();
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

#[derive(Clone, Copy)]
pub enum Axis {
    X,
    Y,
    Z,
}

/// Rotation about a coordinate axis.
pub fn rotate(axis: Axis, angle: f64) -> Mat4 {
    let mut m = zero();
    let (c, s) = (angle.cos(), angle.sin());
    match axis {
        Axis::X => {
            m[0][0] = 1.0;
            m[1][1] = c;
            m[2][2] = c;
            m[1][2] = s;
            m[2][1] = -s;
        }
        Axis::Y => {
            m[1][1] = 1.0;
            m[0][0] = c;
            m[2][2] = c;
            m[2][0] = s;
            m[0][2] = -s;
        }
        Axis::Z => {
            m[2][2] = 1.0;
            m[0][0] = c;
            m[1][1] = c;
            m[0][1] = s;
            m[1][0] = -s;
        }
    }
    m[3][3] = 1.0;
    m
}

/// Rotation by `angle` about the unit vector `a`.
pub fn axis_rotate(a: [f64; 3], angle: f64) -> Mat4 {
    let (c, s) = (angle.cos(), angle.sin());
    let omc = 1.0 - c;
    let [x, y, z] = a;
    [
        [
            x * x + (1.0 - x * x) * c,
            x * y * omc + z * s,
            x * z * omc - y * s,
            0.0,
        ],
        [
            x * y * omc - z * s,
            y * y + (1.0 - y * y) * c,
            y * z * omc + x * s,
            0.0,
        ],
        [
            x * z * omc + y * s,
            y * z * omc - x * s,
            z * z + (1.0 - z * z) * c,
            0.0,
        ],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

pub fn multiply(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut r = zero();
    for i in 0..4 {
        for j in 0..4 {
            r[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] + a[i][3] * b[3][j];
        }
    }
    r
}

pub fn transpose(m: &Mat4) -> Mat4 {
    let mut r = zero();
    for i in 0..4 {
        for j in 0..4 {
            r[j][i] = m[i][j];
        }
    }
    r
}

/// Direction times matrix (no translation).
pub fn transform_vector(v: [f64; 3], m: &Mat4) -> [f64; 3] {
    [
        v[0] * m[0][0] + v[1] * m[1][0] + v[2] * m[2][0],
        v[0] * m[0][1] + v[1] * m[1][1] + v[2] * m[2][1],
        v[0] * m[0][2] + v[1] * m[1][2] + v[2] * m[2][2],
    ]
}

/// Point times matrix (with translation).
pub fn transform_point(v: [f64; 3], m: &Mat4) -> [f64; 3] {
    [
        v[0] * m[0][0] + v[1] * m[1][0] + v[2] * m[2][0] + m[3][0],
        v[0] * m[0][1] + v[1] * m[1][1] + v[2] * m[2][1] + m[3][1],
        v[0] * m[0][2] + v[1] * m[1][2] + v[2] * m[2][2] + m[3][2],
    ]
}

/// Homogeneous 4-vector times matrix.
pub fn transform_coord(v: [f64; 4], m: &Mat4) -> [f64; 4] {
    let mut r = [0.0; 4];
    for (j, out) in r.iter_mut().enumerate() {
        *out = v[0] * m[0][j] + v[1] * m[1][j] + v[2] * m[2][j] + v[3] * m[3][j];
    }
    r
}

pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Normalizes in place unless the vector is zero, as the SPD does.
pub fn normalize(v: &mut [f64; 3]) {
    let d = dot(*v, *v).sqrt();
    if d > 0.0 {
        v[0] /= d;
        v[1] /= d;
        v[2] /= d;
    }
}

pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
