//! Pixel geometry for point labels and the legend: where text fits without
//! covering markers, lines, bars or other text.

/// A pixel position, as plotters' backends use them.
pub type Px = (i32, i32);

/// An axis-aligned box in pixels, `x0 <= x1`, `y0 <= y1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x0: i32,
    pub y0: i32,
    pub x1: i32,
    pub y1: i32,
}

impl Rect {
    /// The box of size `(w, h)` whose top left corner is `(x, y)`.
    pub fn at((x, y): Px, (w, h): (i32, i32)) -> Rect {
        Rect {
            x0: x,
            y0: y,
            x1: x + w,
            y1: y + h,
        }
    }

    /// The box spanning two corners given in any order.
    pub fn spanning(a: Px, b: Px) -> Rect {
        Rect {
            x0: a.0.min(b.0),
            y0: a.1.min(b.1),
            x1: a.0.max(b.0),
            y1: a.1.max(b.1),
        }
    }

    /// The same box with `by` pixels more on every side.
    pub fn grow(&self, by: i32) -> Rect {
        Rect {
            x0: self.x0 - by,
            y0: self.y0 - by,
            x1: self.x1 + by,
            y1: self.y1 + by,
        }
    }

    pub fn overlaps(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }

    pub fn contains(&self, o: &Rect) -> bool {
        self.x0 <= o.x0 && o.x1 <= self.x1 && self.y0 <= o.y0 && o.y1 <= self.y1
    }

    /// Whether the segment from `a` to `b` passes through the box
    /// (Liang-Barsky clipping).
    pub fn crosses(&self, a: Px, b: Px) -> bool {
        let (x, y) = (a.0 as f64, a.1 as f64);
        let (dx, dy) = ((b.0 - a.0) as f64, (b.1 - a.1) as f64);
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, q) in [
            (-dx, x - self.x0 as f64),
            (dx, self.x1 as f64 - x),
            (-dy, y - self.y0 as f64),
            (dy, self.y1 as f64 - y),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return false;
                }
            } else if p < 0.0 {
                t0 = t0.max(q / p);
            } else {
                t1 = t1.min(q / p);
            }
        }
        t0 <= t1
    }
}

/// The size in pixels of one line of text at a font size of `px` pixels.
/// Nothing measures the font (plotters' SVG backend leaves that to the
/// viewer), so this assumes DejaVu Sans, the usual `sans-serif`, whose
/// characters average about 0.6 em; a generous estimate keeps labels apart.
pub fn text_size(text: &str, px: f64) -> (i32, i32) {
    let w = text.chars().count() as f64 * 0.6 * px;
    (w.ceil() as i32, (1.25 * px).ceil() as i32)
}

/// What labels and the legend should not cover.
#[derive(Default)]
pub struct Obstacles {
    /// Markers and bars.
    pub marks: Vec<Rect>,
    /// The lines between markers.
    pub segments: Vec<(Px, Px)>,
    /// Labels already placed.
    pub texts: Vec<Rect>,
}

impl Obstacles {
    /// How badly a box at `r` would cover what is already drawn: covering
    /// text is worst, then markers and bars, then lines, which can be
    /// followed on either side of a label.
    pub fn cost(&self, r: &Rect) -> u32 {
        self.weigh(r, |_| *r)
    }

    /// The cost of a label at `r` for the point `p`, with a little room
    /// around the text so that lines do not graze it; but not around lines
    /// that start at `p` itself, which every label beside it must touch.
    fn cost_beside(&self, r: &Rect, p: Px) -> u32 {
        let padded = r.grow(2);
        self.weigh(&padded, |(a, b)| if a == p || b == p { *r } else { padded })
    }

    /// Weighted count of texts and marks overlapping `r`, and segments
    /// crossing the box `for_segment` chooses for each.
    fn weigh(&self, r: &Rect, for_segment: impl Fn((Px, Px)) -> Rect) -> u32 {
        let texts = self.texts.iter().filter(|t| t.overlaps(r)).count() as u32;
        let marks = self.marks.iter().filter(|m| m.overlaps(r)).count() as u32;
        let lines = self
            .segments
            .iter()
            .filter(|&&(a, b)| for_segment((a, b)).crosses(a, b))
            .count() as u32;
        100 * texts + 20 * marks + 10 * lines
    }

    /// How badly a leader from `p` to `end` would cross text already placed.
    fn leader_cost(&self, p: Px, end: Px) -> u32 {
        50 * self.texts.iter().filter(|t| t.crosses(p, end)).count() as u32
    }
}

/// Gap in pixels between a marker's centre and its label, and how much
/// further each ring of more distant places is.
const GAP: i32 = 6;
const RING: i32 = 16;
const RINGS: i32 = 4;

/// Where a point's label goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placed {
    pub rect: Rect,
    /// Whether the label is far enough from its point to need a line to it.
    pub leader: bool,
}

/// The box for a label of `size` beside the marker at `p`, inside `plot`,
/// covering least. Right, above right, below right, above, below, left,
/// above left and below left of the marker are tried first; where points
/// crowd, the same directions further out, joined to the point by a leader.
pub fn place_label(p: Px, size: (i32, i32), plot: &Rect, obstacles: &Obstacles) -> Placed {
    let score = |&(r, ring): &(Rect, i32)| {
        let outside = if plot.contains(&r) { 0 } else { 10_000 };
        let leader = if ring > 0 {
            obstacles.leader_cost(p, nearest(&r, p))
        } else {
            0
        };
        // Distance costs a little, less than crossing a line, so a near
        // place wins unless it covers something.
        outside + obstacles.cost_beside(&r, p) + leader + 2 * ring as u32
    };
    let best = (0..RINGS)
        .flat_map(|ring| around(p, size, GAP + ring * RING).map(move |r| (r, ring)))
        .min_by_key(score);
    match best {
        Some((rect, ring)) => Placed {
            rect,
            leader: ring > 0,
        },
        None => Placed {
            rect: Rect::at((p.0 + GAP, p.1 - size.1 / 2), size),
            leader: false,
        },
    }
}

/// Boxes of `size` in eight directions around `p`, `gap` pixels away.
fn around(p: Px, (w, h): (i32, i32), gap: i32) -> impl Iterator<Item = Rect> {
    let (x, y) = p;
    // Diagonals sit closer, as a box's corner is further out than its side.
    let d = gap / 2;
    [
        (x + gap, y - h / 2),
        (x + d, y - gap - h),
        (x + d, y + gap),
        (x - w / 2, y - gap - h),
        (x - w / 2, y + gap),
        (x - gap - w, y - h / 2),
        (x - d - w, y - gap - h),
        (x - d - w, y + gap),
    ]
    .into_iter()
    .map(move |c| Rect::at(c, (w, h)))
}

/// The point of `r` nearest to `p`, where a leader from `p` should end.
pub fn nearest(r: &Rect, p: Px) -> Px {
    (p.0.clamp(r.x0, r.x1), p.1.clamp(r.y0, r.y1))
}

/// Inset in pixels of the legend from the edge of the plot.
const INSET: i32 = 8;

/// The first place inside `plot` (upper right, upper left, lower right,
/// lower left, top middle, bottom middle) where a legend of `size` covers
/// nothing at all, with a little room around it; `None` when there is none.
pub fn free_corner(plot: &Rect, size: (i32, i32), obstacles: &Obstacles) -> Option<Rect> {
    let (w, h) = size;
    let (left, right) = (plot.x0 + INSET, plot.x1 - INSET - w);
    let (top, bottom) = (plot.y0 + INSET, plot.y1 - INSET - h);
    let middle = (plot.x0 + plot.x1 - w) / 2;
    [
        (right, top),
        (left, top),
        (right, bottom),
        (left, bottom),
        (middle, top),
        (middle, bottom),
    ]
    .into_iter()
    .map(|c| Rect::at(c, size))
    .find(|r| plot.contains(r) && obstacles.cost(&r.grow(4)) == 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const PLOT: Rect = Rect {
        x0: 0,
        y0: 0,
        x1: 400,
        y1: 300,
    };

    #[test]
    fn segments_cross_boxes_they_pass_through() {
        let r = Rect::at((10, 10), (10, 10));
        assert!(r.crosses((0, 0), (30, 30)));
        assert!(r.crosses((15, 0), (15, 40)));
        assert!(r.crosses((12, 12), (13, 13)));
        assert!(!r.crosses((0, 0), (30, 0)));
        assert!(!r.crosses((0, 30), (30, 60)));
    }

    #[test]
    fn labels_go_right_unless_something_is_there() {
        let none = Obstacles::default();
        let size = (40, 14);
        let r = place_label((100, 100), size, &PLOT, &none);
        assert_eq!(
            r,
            Placed {
                rect: Rect::at((106, 93), size),
                leader: false
            }
        );
        // A label already to the right: go elsewhere, without covering it.
        let taken = Obstacles {
            texts: vec![Rect::at((106, 93), size)],
            ..Obstacles::default()
        };
        let r2 = place_label((100, 100), size, &PLOT, &taken).rect;
        assert!(!r2.overlaps(&taken.texts[0]), "{r2:?}");
        // At the right edge of the plot: go left, staying inside.
        let r3 = place_label((395, 100), size, &PLOT, &none).rect;
        assert!(PLOT.contains(&r3) && r3.x1 < 395, "{r3:?}");
    }

    #[test]
    fn crowded_labels_move_out_with_a_leader() {
        let size = (40, 14);
        // Every near place is taken by another label.
        let taken = Obstacles {
            texts: around((200, 150), size, GAP).collect(),
            ..Obstacles::default()
        };
        let p = place_label((200, 150), size, &PLOT, &taken);
        assert!(p.leader, "{p:?}");
        assert!(taken.texts.iter().all(|t| !t.overlaps(&p.rect)), "{p:?}");
        let end = nearest(&p.rect, (200, 150));
        assert!(p.rect.contains(&Rect::at(end, (0, 0))), "{p:?} {end:?}");
    }

    #[test]
    fn legend_avoids_corners_with_data() {
        let size = (100, 40);
        let mut data = Obstacles::default();
        assert_eq!(
            free_corner(&PLOT, size, &data).map(|r| (r.x0, r.y0)),
            Some((292, 8))
        );
        // A line rising to the upper right: the legend goes upper left.
        data.segments.push(((0, 300), (400, 0)));
        assert_eq!(
            free_corner(&PLOT, size, &data).map(|r| (r.x0, r.y0)),
            Some((8, 8))
        );
        // Markers everywhere: no room inside.
        for x in (0..400).step_by(20) {
            for y in (0..300).step_by(20) {
                data.marks.push(Rect::at((x, y), (4, 4)));
            }
        }
        assert_eq!(free_corner(&PLOT, size, &data), None);
    }
}
