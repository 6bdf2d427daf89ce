//! Region filling (thesis §3.3–3.4, SPEC §4.2 step 5): a traversable
//! pocket fully enclosed by obstacles cannot be reached, so when it is
//! smaller than a minimum area it becomes an obstacle too.
//!
//! Pockets are 4-connected: the route planner does not cut corners past
//! obstacle cells, so two traversable cells touching only at a corner
//! between obstacles are not connected for it either. A region touching
//! the grid's edge or an unknown cell may continue beyond what is known,
//! so it is never filled.

use super::Class;

/// Marks every enclosed traversable region of fewer than `min_cells`
/// cells as [`Class::Enclosed`]; returns how many regions were filled.
pub fn fill_enclosed(class: &mut [u8], width: usize, height: usize, min_cells: f64) -> usize {
    const SEEN: u8 = 0x80;
    let trav = Class::Traversable as u8;
    let mut stack: Vec<usize> = Vec::new();
    let mut region: Vec<usize> = Vec::new();
    let mut filled = 0;
    for start in 0..class.len() {
        if class[start] != trav {
            continue;
        }
        // Flood the region, noting whether it escapes.
        class[start] |= SEEN;
        stack.push(start);
        region.clear();
        let mut open = false;
        while let Some(i) = stack.pop() {
            // Only regions that may be filled need their cells listed.
            if !open {
                region.push(i);
            }
            let (c, r) = (i % width, i / width);
            if c == 0 || r == 0 || c + 1 == width || r + 1 == height {
                open = true;
            }
            let mut visit = |j: usize| {
                let k = class[j];
                if k == trav {
                    class[j] |= SEEN;
                    stack.push(j);
                } else if k == Class::Unknown as u8 {
                    open = true;
                }
            };
            if c > 0 {
                visit(i - 1);
            }
            if c + 1 < width {
                visit(i + 1);
            }
            if r > 0 {
                visit(i - width);
            }
            if r + 1 < height {
                visit(i + width);
            }
        }
        if !open && (region.len() as f64) < min_cells {
            for &i in &region {
                class[i] = Class::Enclosed as u8 | SEEN;
            }
            filled += 1;
        }
    }
    for k in class.iter_mut() {
        *k &= !SEEN;
    }
    filled
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid from rows of '.', '#' (slope obstacle) and '?' (unknown).
    fn grid(rows: &[&str]) -> (Vec<u8>, usize, usize) {
        let w = rows[0].len();
        let cells = rows
            .iter()
            .flat_map(|r| r.chars())
            .map(|ch| match ch {
                '.' => Class::Traversable as u8,
                '#' => Class::Slope as u8,
                _ => Class::Unknown as u8,
            })
            .collect();
        (cells, w, rows.len())
    }

    #[test]
    fn small_enclosed_pockets_are_filled_and_large_or_open_ones_kept() {
        let (mut g, w, h) = grid(&[
            "..........",
            ".####.###.",
            ".#..#.#.#.",
            ".####.###.",
            "..........",
            "#####.....",
            "#...#.....",
            "#...#..#?#",
            "#####..#.#",
            ".......###",
        ]);
        // Pockets: 2 cells (row 2, cols 2–3), 1 cell (row 2, col 7),
        // 6 cells (rows 6–7, cols 1–3), and one cell (row 8, col 8)
        // touching an unknown cell.
        let filled = fill_enclosed(&mut g, w, h, 3.0);
        assert_eq!(filled, 2);
        let at = |g: &[u8], r: usize, c: usize| Class::from_code(g[r * w + c]).unwrap();
        assert_eq!(at(&g, 2, 2), Class::Enclosed);
        assert_eq!(at(&g, 2, 3), Class::Enclosed);
        assert_eq!(at(&g, 2, 7), Class::Enclosed);
        assert_eq!(at(&g, 6, 1), Class::Traversable, "6 cells ≥ 3");
        assert_eq!(at(&g, 8, 8), Class::Traversable, "touches unknown");
        assert_eq!(at(&g, 0, 0), Class::Traversable);
        // A larger limit fills the 6-cell pocket too.
        let filled = fill_enclosed(&mut g, w, h, 7.0);
        assert_eq!(filled, 1);
        assert_eq!(at(&g, 7, 3), Class::Enclosed);
    }

    #[test]
    fn corner_contact_does_not_connect() {
        let (mut g, w, h) = grid(&["....", ".##.", ".#.#", "..#."]);
        // (2,2) touches the open area only diagonally: enclosed; (3,3) is
        // on the edge.
        assert_eq!(fill_enclosed(&mut g, w, h, 2.0), 1);
        assert_eq!(g[2 * w + 2], Class::Enclosed as u8);
        assert_eq!(g[3 * w + 3], Class::Traversable as u8);
    }
}
