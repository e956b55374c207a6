//! A job's render settings as they travel (`RenderParams`) and as the
//! engine takes them.

use sray_engine::bf::StoreNumber;
use sray_engine::render::{Aggregates, GridRes, Precision, RenderOptions};
use sray_proto::v1;

/// The settings of a job, to send.
pub fn to_proto(o: &RenderOptions, store: StoreNumber) -> v1::RenderParams {
    let [x, y, z] = match o.grid_res {
        GridRes::Auto => [0; 3],
        GridRes::Fixed(r) => r,
    };
    v1::RenderParams {
        width: o.width,
        height: o.height,
        max_depth: o.max_depth as u32,
        grid_res_x: x,
        grid_res_y: y,
        grid_res_z: z,
        grid_density: o.grid_density,
        multiple_grids: o.multiple_grids,
        precision: match o.precision {
            Precision::Double => v1::Precision::Double,
            Precision::Single => v1::Precision::Single,
        } as i32,
        store_number: match store {
            StoreNumber::Fixed(n) => n.max(1),
            StoreNumber::Adaptive | StoreNumber::Budget => 0,
        },
        store_budget: store == StoreNumber::Budget,
        samples: o.samples,
        no_aggregates: o.aggregates == Aggregates::Off,
    }
}

/// The engine's settings from received ones, with this node's thread
/// count; checked as the command line's are.
pub fn from_proto(
    p: &v1::RenderParams,
    threads: usize,
) -> Result<(RenderOptions, StoreNumber), String> {
    let grid_res = match [p.grid_res_x, p.grid_res_y, p.grid_res_z] {
        [0, 0, 0] => GridRes::Auto,
        r if r.iter().all(|&n| (1..=4096).contains(&n)) => GridRes::Fixed(r),
        r => return Err(format!("grid resolution {r:?} is out of range")),
    };
    let max_depth =
        u8::try_from(p.max_depth).map_err(|_| format!("depth {} is out of range", p.max_depth))?;
    let o = RenderOptions {
        width: p.width,
        height: p.height,
        max_depth,
        threads,
        grid_res,
        grid_density: p.grid_density,
        multiple_grids: p.multiple_grids,
        aggregates: if p.no_aggregates {
            Aggregates::Off
        } else {
            Aggregates::Auto
        },
        precision: match v1::Precision::try_from(p.precision) {
            Ok(v1::Precision::Single) => Precision::Single,
            Ok(v1::Precision::Double) => Precision::Double,
            Err(_) => return Err(format!("unknown precision {}", p.precision)),
        },
        profile: false,
        samples: p.samples,
        // Each node runs the widest kernels it has (or SRAY_SIMD's): the
        // results are the same bits on every width.
        simd: None,
    };
    o.validate().map_err(|e| e.to_string())?;
    let store = match (p.store_number, p.store_budget) {
        (0, false) => StoreNumber::Adaptive,
        (0, true) => StoreNumber::Budget,
        (n, _) => StoreNumber::Fixed(n),
    };
    Ok((o, store))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_survive_the_trip() {
        let o = RenderOptions {
            width: 33,
            height: 17,
            max_depth: 3,
            grid_res: GridRes::Fixed([4, 5, 6]),
            grid_density: 2.5,
            multiple_grids: false,
            aggregates: Aggregates::Off,
            precision: Precision::Single,
            threads: 7,
            samples: 9,
            ..Default::default()
        };
        let (back, store) = from_proto(&to_proto(&o, StoreNumber::Fixed(3)), 7).unwrap();
        assert_eq!(format!("{o:?}"), format!("{back:?}"));
        assert_eq!(store, StoreNumber::Fixed(3));
        for store in [StoreNumber::Budget, StoreNumber::Adaptive] {
            assert_eq!(from_proto(&to_proto(&o, store), 1).unwrap().1, store);
        }
        let mut p = to_proto(&o, StoreNumber::Adaptive);
        p.max_depth = 1000;
        assert!(from_proto(&p, 1).is_err());
        p.max_depth = 2;
        p.width = 0;
        assert!(from_proto(&p, 1).is_err());
    }
}
