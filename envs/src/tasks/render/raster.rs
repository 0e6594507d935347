//! A small software rasterizer for the GIF writer: an indexed-colour image (one palette index
//! per pixel) and one primitive, the *capsule*: every pixel whose centre lies within a radius
//! of a segment. A capsule is a thick line with round caps, a disc when its end points
//! coincide. No anti-aliasing (the palette is fixed) and no depth buffer (the caller draws
//! in painter's order, far to near).

/// An indexed-colour image, row-major, `width * height` palette indices.
#[derive(Clone, Debug)]
pub(super) struct Canvas {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Palette index of every pixel, row after row.
    pub pixels: Vec<u8>,
}

impl Canvas {
    /// A `width` x `height` image filled with colour `fill`.
    pub fn new(width: usize, height: usize, fill: u8) -> Canvas {
        Canvas { width, height, pixels: vec![fill; width * height] }
    }

    /// Paints `colour` on every pixel whose centre is within `radius` of the segment from `a`
    /// to `b` (pixel coordinates: x right, y down, pixel `(i, j)` centred at `(i + 0.5, j + 0.5)`).
    /// Parts outside the image are clipped; a non-finite or negative input draws nothing.
    pub fn capsule(&mut self, a: [f64; 2], b: [f64; 2], radius: f64, colour: u8) {
        if !(a.iter().chain(&b).all(|v| v.is_finite()) && radius.is_finite() && radius >= 0.0) {
            return;
        }
        // Pixel ranges of the bounding box, clamped to the image before any cast.
        let range = |lo: f64, hi: f64, n: usize| {
            let lo = (lo - radius - 0.5).floor().max(0.0);
            let hi = (hi + radius - 0.5).ceil().min(n as f64 - 1.0);
            (lo as usize, hi as usize, lo <= hi)
        };
        let (x0, x1, x_ok) = range(a[0].min(b[0]), a[0].max(b[0]), self.width);
        let (y0, y1, y_ok) = range(a[1].min(b[1]), a[1].max(b[1]), self.height);
        if !(x_ok && y_ok) {
            return;
        }
        let d = [b[0] - a[0], b[1] - a[1]];
        let len2 = d[0] * d[0] + d[1] * d[1];
        let r2 = radius * radius;
        for y in y0..=y1 {
            let py = y as f64 + 0.5 - a[1];
            let row = &mut self.pixels[y * self.width..(y + 1) * self.width];
            for (x, pixel) in row.iter_mut().enumerate().take(x1 + 1).skip(x0) {
                let px = x as f64 + 0.5 - a[0];
                // Squared distance from the pixel centre to the nearest point of the segment.
                let t = if len2 > 0.0 { ((px * d[0] + py * d[1]) / len2).clamp(0.0, 1.0) } else { 0.0 };
                let (ex, ey) = (px - t * d[0], py - t * d[1]);
                if ex * ex + ey * ey <= r2 {
                    *pixel = colour;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Canvas;

    #[test]
    fn a_disc_covers_the_pixels_within_its_radius() {
        let mut c = Canvas::new(10, 10, 0);
        c.capsule([5.0, 5.0], [5.0, 5.0], 2.0, 3);
        // Pixel centres within distance 2 of (5, 5): offsets (+-0.5, +-1.5) and so on: 12 pixels.
        assert_eq!(c.pixels.iter().filter(|&&p| p == 3).count(), 12);
        assert_eq!(c.pixels[5 * 10 + 5], 3);
        assert_eq!(c.pixels[0], 0);
    }

    #[test]
    fn a_horizontal_capsule_is_a_band_with_round_caps_and_clipping_is_safe() {
        let mut c = Canvas::new(20, 5, 0);
        c.capsule([2.0, 2.5], [17.0, 2.5], 0.6, 1);
        // One row thick (centres at y = 2.5): the centres x = 1.5 ..= 17.5 are within 0.6 of it.
        let row: Vec<u8> = c.pixels[2 * 20..3 * 20].to_vec();
        assert_eq!(row.iter().filter(|&&p| p == 1).count(), 17);
        assert_eq!(c.pixels.iter().filter(|&&p| p == 1).count(), 17);
        // Far outside, huge, or not finite: nothing drawn, no panic.
        let before = c.pixels.clone();
        c.capsule([-1e300, -5.0], [-1e299, -7.0], 3.0, 2);
        c.capsule([f64::NAN, 0.0], [1.0, 1.0], 3.0, 2);
        c.capsule([100.0, 100.0], [100.0, 100.0], 5.0, 2);
        assert_eq!(c.pixels, before);
        c.capsule([-1e9, 2.5], [1e9, 2.5], 0.6, 2);
        assert_eq!(c.pixels[2 * 20..3 * 20], [2u8; 20]);
    }
}
