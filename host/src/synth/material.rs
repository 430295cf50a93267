//! Surface materials: what each primitive looks like, as a function of its surface
//! coordinates `(u, v)` in metres and the pixel footprint `fp` (metres per pixel).
//!
//! Conventions: on vertical faces `u` runs left to right as seen from outside the face and `v` is
//! the height above the ground; on the road and pavements (`Strip` mapping) `u` is the arc
//! length `s` along the road and `v` the lateral offset (positive to the right of the direction
//! of travel).

use super::texture::{
    add, disc, fbm, ffloor, fract, grain, hash3, ifloor, line1, lines, lod, mix, pick, rect, rnd,
    scale, text, vnoise, Rgb,
};

/// Which face of a vehicle a primitive is; decides where windows, lights and wheels go.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum VPart {
    /// Lower body, side (u along the car from the face's left edge).
    BodySide,
    /// Lower body, front.
    BodyFront,
    /// Lower body, back.
    BodyBack,
    /// Cabin/greenhouse sides.
    CabinSide,
    /// Windscreen.
    CabinFront,
    /// Rear window.
    CabinBack,
    /// Roof and bonnet tops.
    Top,
    /// A wheel's faces.
    Wheel,
    /// Box body of a van/truck, side.
    CargoSide,
    /// Box body of a van/truck, rear doors.
    CargoBack,
}

/// Which part of a person (pedestrian or rider).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum PPart {
    /// Torso, `front` when facing the viewer side of the body's forward.
    Torso,
    /// Legs and trousers.
    Legs,
    /// Head (hair all round, face at the front).
    Head {
        /// Face side.
        front: bool,
    },
}

/// A building front's look.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FacadeStyle {
    /// Wall colour.
    pub base: Rgb,
    /// 0 brick, 1 plaster, 2 stone blocks.
    pub kind: u8,
    /// Floor height (m).
    pub floor_h: f32,
    /// Ground floor height (m).
    pub ground_h: f32,
    /// Window bay spacing (m).
    pub bay: f32,
    /// Window width and height (m).
    pub win: [f32; 2],
    /// Shops on the ground floor.
    pub shop: bool,
    /// Window frame colour.
    pub frame: Rgb,
    /// Facade length (m): windows stay clear of its ends.
    pub len: f32,
    /// Seed of the per-window and per-brick variation.
    pub seed: u32,
}

/// A primitive's material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Mat {
    /// Main road (Strip mapping); `zebra` draws a pedestrian crossing over the whole strip.
    Road {
        /// Zebra crossing on this strip.
        zebra: bool,
    },
    /// Side street asphalt (affine).
    SideRoad,
    /// Paving slabs (Strip).
    Pavement,
    /// Gravel and dirt behind the pavement (Strip).
    Yard,
    /// Kerb stones.
    Kerb,
    /// A building front.
    Facade(FacadeStyle),
    /// Plain rendered wall (building sides and backs).
    Wall {
        /// Colour.
        base: Rgb,
        /// Variation seed.
        seed: u32,
    },
    /// Painted or galvanised metal (poles, sign backs, light housings).
    Metal {
        /// Colour.
        base: Rgb,
    },
    /// A traffic sign plate, cut out to its shape; `u, v` centred on the plate.
    Sign {
        /// 0 round prohibitory, 1 triangle warning, 2 square blue, 3 round blue.
        kind: u8,
    },
    /// The grey back of a sign plate, same cut-out.
    SignBack {
        /// Shape as in [`Mat::Sign`].
        kind: u8,
    },
    /// Traffic light housing front with three lamps (`u, v` from the housing's corner).
    TrafficLight {
        /// Lit lamp: 0 red, 1 amber, 2 green.
        state: u8,
    },
    /// Tree bark.
    Bark,
    /// A tree crown billboard, cut out to a ragged ellipse (`u, v` from its corner).
    Leaves {
        /// Crown width and height (m).
        size: [f32; 2],
        /// Variation seed.
        seed: u32,
    },
    /// A trimmed hedge box.
    Hedge,
    /// A fence: 0 metal bars (cut out), 1 wooden planks.
    Fence {
        /// Fence kind.
        kind: u8,
    },
    /// Vehicle surface.
    Vehicle {
        /// Paint colour.
        paint: Rgb,
        /// Which face.
        part: VPart,
        /// Face width (m) and the height of the face's bottom above the ground (m).
        dims: [f32; 2],
        /// Variation seed.
        seed: u32,
    },
    /// Person surface.
    Person {
        /// Top and bottom clothing colours.
        cloth: [Rgb; 2],
        /// Which part.
        part: PPart,
        /// Variation seed.
        seed: u32,
    },
    /// A bicycle side, cut out to wheels and frame (`u` along, `v` height).
    Bike,
}

impl Mat {
    /// Whether the material has holes (decided per pixel at rasterisation).
    pub(crate) fn is_cutout(&self) -> bool {
        match self {
            Mat::Sign { .. } | Mat::SignBack { .. } | Mat::Leaves { .. } | Mat::Bike => true,
            Mat::Fence { kind } => *kind == 0,
            _ => false,
        }
    }

    /// Whether the surface point `(u, v)` is solid (cut-out materials only; others: true).
    pub(crate) fn alpha(&self, u: f32, v: f32) -> bool {
        match *self {
            Mat::Sign { kind } | Mat::SignBack { kind } => sign_shape(kind, u, v) >= 0.0,
            Mat::Leaves { size, seed } => {
                let (a, b) = (size[0] * 0.5, size[1] * 0.5);
                let (x, y) = ((u - a) / a, (v - b) / b);
                let r2 = x * x + y * y;
                let ragged = 0.75 + 0.35 * vnoise(u * 1.3, v * 1.3, seed);
                if r2 > ragged * ragged {
                    return false;
                }
                // Holes in the foliage, more towards the rim.
                vnoise(u * 2.7, v * 2.7, seed ^ 0x55) + 0.55 * (1.0 - r2) > 0.45
            }
            Mat::Fence { kind: 0 } => {
                let bar = (fract(u / 0.14 + 0.5) - 0.5).abs() * 0.14 < 0.022;
                let rail = (v - 0.12).abs() < 0.03 || (v - 1.1).abs() < 0.035;
                (bar || rail) && v < 1.16
            }
            Mat::Bike => bike_shape(u, v),
            _ => true,
        }
    }

    /// Surface colour at `(u, v)`.
    pub(crate) fn shade(&self, u: f32, v: f32, fp: f32) -> Rgb {
        match *self {
            Mat::Road { zebra } => road(u, v, fp, zebra),
            Mat::SideRoad => {
                let mut c = asphalt(u, v, fp, 9);
                // Stop line across the side street, near the junction.
                let stop = line1(u - 2.5, 0.3, fp);
                c = mix(c, [200.0, 200.0, 195.0], stop * 0.9);
                c
            }
            Mat::Pavement => pavement(u, v, fp),
            Mat::Yard => {
                let n = fbm(u, v, 0.4, 3, fp, 31);
                let g = grain(u, v, 0.03, fp, 32);
                let grass = vnoise(u * 0.15, v * 0.15, 33);
                let dirt = [128.0 + 20.0 * n, 116.0 + 18.0 * n, 98.0 + 14.0 * n];
                let green = [80.0 + 25.0 * n, 100.0 + 30.0 * n, 60.0 + 15.0 * n];
                add(mix(dirt, green, ((grass - 0.4) * 3.0).clamp(0.0, 1.0)), 14.0 * g)
            }
            Mat::Kerb => {
                let joint = lines(u, 1.0, 0.015, fp);
                let b = 150.0 + 15.0 * fbm(u, v, 2.0, 3, fp, 41) + 10.0 * grain(u, v, 0.02, fp, 42);
                let b = b * (1.0 - 0.5 * joint);
                [b, b, b * 0.98]
            }
            Mat::Facade(st) => facade(&st, u, v, fp),
            Mat::Wall { base, seed } => {
                let n = fbm(u, v, 0.5, 3, fp, seed);
                let stain = (1.0 - v / 3.0).clamp(0.0, 1.0) * 0.15;
                let mut c = scale(add(base, 16.0 * n), 1.0 - stain);
                // A few small windows on side walls.
                let bay = ffloor(u / 3.1);
                let fl = ffloor(v / 3.2);
                if fl >= 1.0 && rnd(bay as i32, fl as i32, seed) < 0.35 {
                    let w = rect(u - bay * 3.1, v - fl * 3.2, 1.0, 1.9, 1.0, 2.2, fp);
                    c = mix(c, [45.0, 52.0, 60.0], w);
                }
                c
            }
            Mat::Metal { base } => {
                let n = fbm(u, v, 3.0, 2, fp, 51);
                add(base, 10.0 * n + 6.0 * grain(u, v, 0.01, fp, 52))
            }
            Mat::Sign { kind } => sign(kind, u, v, fp),
            Mat::SignBack { .. } => [120.0, 122.0, 125.0],
            Mat::TrafficLight { state } => {
                let mut c: Rgb = [32.0, 34.0, 30.0];
                for k in 0..3u8 {
                    let cy = 0.8 - 0.3 * k as f32;
                    let d = disc(u, v, 0.175, cy, 0.1, fp);
                    let lit = k == state;
                    let col: Rgb = match (k, lit) {
                        (0, true) => [255.0, 60.0, 40.0],
                        (1, true) => [255.0, 190.0, 40.0],
                        (2, true) => [80.0, 255.0, 150.0],
                        _ => [70.0, 70.0, 66.0],
                    };
                    c = mix(c, col, d);
                    // Visor shadow above each lamp.
                    c = mix(c, [12.0, 12.0, 12.0], rect(u, v, 0.04, 0.31, cy + 0.1, cy + 0.13, fp));
                }
                c
            }
            Mat::Bark => {
                let streak = vnoise(u * 14.0, v * 1.5, 61);
                let b = 70.0 + 35.0 * streak * lod(14.0, fp) + 12.0 * grain(u, v, 0.02, fp, 62);
                [b, b * 0.92, b * 0.8]
            }
            Mat::Leaves { seed, .. } => leaves(u, v, fp, seed),
            Mat::Hedge => {
                let c = leaves(u, v, fp, 77);
                scale(c, 0.85)
            }
            Mat::Fence { kind } => {
                if kind == 0 {
                    [60.0, 64.0, 62.0]
                } else {
                    let plank = lines(u, 0.15, 0.015, fp);
                    let w = 120.0 + 25.0 * fbm(u * 0.3, v * 3.0, 2.0, 3, fp, 71);
                    let c = [w, w * 0.78, w * 0.55];
                    scale(c, 1.0 - 0.6 * plank)
                }
            }
            Mat::Vehicle { paint, part, dims, seed } => vehicle(paint, part, dims, seed, u, v, fp),
            Mat::Person { cloth, part, seed } => person(cloth, part, seed, u, v, fp),
            Mat::Bike => {
                let c = 40.0 + 20.0 * grain(u, v, 0.03, fp, 81);
                [c, c, c * 1.1]
            }
        }
    }
}

fn asphalt(s: f32, lat: f32, fp: f32, seed: u32) -> Rgb {
    let base = 96.0 + 14.0 * (vnoise(s * 0.4, lat * 0.4, seed) - 0.5);
    let patch = vnoise(s * 0.07, lat * 0.2, seed ^ 3);
    let patch = if patch > 0.72 { -14.0 } else { 0.0 };
    let g = 16.0 * grain(s, lat, 0.025, fp, seed ^ 5) + 9.0 * grain(s, lat, 0.07, fp, seed ^ 6);
    let b = base + patch + g;
    [b, b, b * 1.02]
}

fn road(s: f32, lat: f32, fp: f32, zebra: bool) -> Rgb {
    let mut c = asphalt(s, lat, fp, 1);
    let a = lat.abs();
    let paint: Rgb = [205.0, 205.0, 198.0];
    let mut m: f32 = 0.0;
    // Centre double line, dashed lane lines, solid edge lines, parking bay ticks.
    m = m.max(line1(a - 0.12, 0.12, fp));
    let dash = rect(fract((s + 1000.0) / 9.0) * 9.0, 0.0, 0.0, 3.0, -1.0, 1.0, fp);
    m = m.max(line1(a - 3.2, 0.13, fp) * dash);
    m = m.max(line1(a - 6.45, 0.15, fp));
    if a > 6.55 && a < 8.5 {
        m = m.max(lines(s, 5.5, 0.1, fp) * rect(a, 0.0, 6.5, 8.5, -1.0, 1.0, fp));
    }
    if zebra && a < 6.4 {
        m = m.max(lines(lat, 1.0, 0.5, fp));
    }
    if m > 0.0 {
        let wear = 0.75 + 0.25 * vnoise(s * 3.0, lat * 3.0, 11);
        c = mix(c, paint, (m * wear).min(1.0));
    }
    // Parking strip darker, stained.
    if a > 6.5 {
        c = scale(c, 0.94);
    }
    c
}

fn pavement(s: f32, lat: f32, fp: f32) -> Rgb {
    let (sx, sy) = (0.6, 0.6);
    let i = ffloor(s / sx) as i32;
    let j = ffloor(lat / sy) as i32;
    let var = rnd(i, j, 21) - 0.5;
    let joint = lines(s, sx, 0.012, fp).max(lines(lat, sy, 0.012, fp));
    let b =
        150.0 + 22.0 * var + 9.0 * fbm(s, lat, 1.0, 2, fp, 22) + 12.0 * grain(s, lat, 0.02, fp, 23);
    let b = b * (1.0 - 0.45 * joint);
    [b * 1.01, b, b * 0.96]
}

fn facade(st: &FacadeStyle, u: f32, v: f32, fp: f32) -> Rgb {
    let seed = st.seed;
    let mut c = st.base;
    match st.kind {
        0 => {
            let bh = 0.075;
            let row = ffloor(v / bh);
            let off = if (row as i32) & 1 == 1 { 0.12 } else { 0.0 };
            let col = ffloor((u + off) / 0.24);
            let var = rnd(col as i32, row as i32, seed) - 0.5;
            c = scale(c, 1.0 + 0.3 * var * lod(1.0 / 0.24, fp));
            let mortar = lines(v, bh, 0.012, fp).max(lines(u + off, 0.24, 0.012, fp));
            c = mix(c, [175.0, 168.0, 158.0], mortar * 0.8);
        }
        1 => {
            c = add(c, 12.0 * fbm(u, v, 0.6, 3, fp, seed) + 6.0 * grain(u, v, 0.015, fp, seed));
        }
        _ => {
            let row = ffloor(v / 0.32);
            let off = if (row as i32) & 1 == 1 { 0.35 } else { 0.0 };
            let col = ffloor((u + off) / 0.7);
            let var = rnd(col as i32, row as i32, seed) - 0.5;
            c = add(scale(c, 1.0 + 0.16 * var), 8.0 * fbm(u, v, 1.5, 2, fp, seed));
            let joint = lines(v, 0.32, 0.015, fp).max(lines(u + off, 0.7, 0.015, fp));
            c = scale(c, 1.0 - 0.35 * joint);
        }
    }
    // Grime near the ground and streaks below windows.
    c = scale(c, 1.0 - 0.18 * (1.0 - v / 2.5).clamp(0.0, 1.0));
    let bay = ffloor(u / st.bay);
    let in_bays = bay >= 0.0 && (bay + 1.0) * st.bay <= st.len;
    let bu = u - bay * st.bay - (st.bay - st.win[0]) * 0.5;
    let wh = hash3(bay as i32, 0, seed);
    if v < st.ground_h {
        let gh = st.ground_h;
        if st.shop {
            // Shop sign band with lettering, shop windows, doors.
            let band = rect(v, 0.0, gh - 0.95, gh - 0.25, -1.0, 1.0, fp);
            if band > 0.0 {
                let palette: [Rgb; 6] = [
                    [180.0, 30.0, 30.0],
                    [30.0, 60.0, 150.0],
                    [235.0, 235.0, 225.0],
                    [30.0, 120.0, 60.0],
                    [40.0, 40.0, 42.0],
                    [230.0, 180.0, 40.0],
                ];
                let shop = ifloor(u / 7.0);
                let h = hash3(shop, 1, seed);
                let bg = pick(&palette, h);
                let ink = if bg[0] + bg[1] + bg[2] > 450.0 {
                    [30.0, 30.0, 35.0]
                } else {
                    [245.0, 245.0, 240.0]
                };
                let tx = u - shop as f32 * 7.0 - 0.6;
                let t = if tx < 5.5 { text(tx, v - (gh - 0.82), 0.28, 0.42, fp, h) } else { 0.0 };
                c = mix(c, mix(bg, ink, t), band);
            }
            let win = rect(v, 0.0, 0.45, gh - 1.15, -1.0, 1.0, fp);
            if win > 0.0 && in_bays {
                let pane = rect(bu, v, 0.0, st.win[0] + 0.6, 0.45, gh - 1.15, fp);
                let door = wh.is_multiple_of(4);
                let (gc, stuff): (Rgb, f32) =
                    if door { ([60.0, 45.0, 35.0], 0.0) } else { ([38.0, 44.0, 52.0], 1.0) };
                // Displays behind the glass: blobs of colour.
                let cell = ifloor(bu / 0.35);
                let cr = ifloor(v / 0.3);
                let hb = hash3(cell + bay as i32 * 31, cr, seed ^ 9);
                let blob = if hb.is_multiple_of(3) && stuff > 0.0 {
                    let pal: [Rgb; 4] = [
                        [200.0, 190.0, 170.0],
                        [150.0, 60.0, 60.0],
                        [80.0, 110.0, 160.0],
                        [210.0, 210.0, 210.0],
                    ];
                    (pick(&pal, hb >> 3), lod(3.0, fp))
                } else {
                    (gc, 0.0)
                };
                let glass = mix(gc, blob.0, blob.1 * 0.8);
                let refl = 30.0 * vnoise(u * 0.4, v * 0.4, seed ^ 4);
                c = mix(c, add(glass, refl), pane);
                let mull = line1(bu - (st.win[0] + 0.6) * 0.5, 0.06, fp) * pane;
                c = mix(c, st.frame, mull);
            }
        } else {
            // Residential ground floor: plinth, doors, barred windows.
            c = mix(c, scale(st.base, 0.7), rect(v, 0.0, -1.0, 0.55, -1.0, 1.0, fp));
            if in_bays {
                if wh.is_multiple_of(5) {
                    let d = rect(bu, v, 0.1, 1.2, 0.0, 2.3, fp);
                    let panel = line1(bu - 0.65, 0.04, fp).max(line1(v - 1.2, 0.04, fp));
                    let door = scale([95.0, 65.0, 45.0], 1.0 - 0.5 * panel);
                    c = mix(c, door, d);
                    c = mix(c, [200.0, 190.0, 150.0], disc(bu, v, 1.0, 1.1, 0.04, fp));
                } else {
                    c = window(c, st, bu, v - 0.9, 1.5, fp, wh);
                }
            }
        }
    } else {
        let rel = v - st.ground_h;
        let fl = ffloor(rel / st.floor_h);
        let fv = rel - fl * st.floor_h;
        // Cornice at each floor.
        let cornice = rect(fv, 0.0, 0.0, 0.18, -1.0, 1.0, fp);
        c = mix(c, scale(st.base, 1.25), cornice * 0.8);
        c = mix(c, scale(st.base, 0.55), rect(fv, 0.0, 0.18, 0.24, -1.0, 1.0, fp) * 0.7);
        if in_bays {
            let h = hash3(bay as i32, fl as i32, seed);
            c = window(c, st, bu, fv - 0.85, st.win[1], fp, h);
        }
    }
    c
}

/// Draws one window (frame, sill, glass with blinds/curtains/reflections) over `c`; `x, y`
/// from the window's bottom-left corner.
fn window(c: Rgb, st: &FacadeStyle, x: f32, y: f32, wh: f32, fp: f32, h: u32) -> Rgb {
    let ww = st.win[0];
    // Sill and lintel.
    let mut c = mix(c, scale(st.frame, 0.9), rect(x, y, -0.1, ww + 0.1, -0.12, 0.0, fp));
    c = mix(c, scale(st.base, 0.8), rect(x, y, -0.05, ww + 0.05, wh, wh + 0.15, fp) * 0.6);
    let outer = rect(x, y, 0.0, ww, 0.0, wh, fp);
    if outer <= 0.0 {
        return c;
    }
    let fr = 0.07;
    let inner = rect(x, y, fr, ww - fr, fr, wh - fr, fp);
    let mut glass: Rgb = [42.0, 50.0, 60.0];
    let refl = vnoise(x * 0.8 + (h & 15) as f32, y * 0.5, st.seed ^ 17);
    glass = add(glass, 45.0 * refl);
    match h % 5 {
        0 => {
            // Roller blind, partly down: horizontal slats.
            let down = wh * (0.3 + 0.6 * ((h >> 4) & 255) as f32 / 255.0);
            if y > wh - down {
                let slat = lines(y, 0.06, 0.015, fp);
                glass = scale([190.0, 186.0, 178.0], 1.0 - 0.35 * slat);
            }
        }
        1 => {
            // Curtains with folds at the sides.
            let edge = 0.25 * ww;
            if x < edge || x > ww - edge {
                let fold = lines(x, 0.08, 0.03, fp);
                glass = scale([210.0, 200.0, 185.0], 1.0 - 0.3 * fold);
            }
        }
        2 => glass = add(glass, 25.0),
        _ => {}
    }
    let mullion = line1(x - ww * 0.5, 0.05, fp).max(line1(y - wh * 0.62, 0.05, fp));
    let pane = mix(glass, st.frame, mullion);
    c = mix(c, st.frame, outer);
    mix(c, pane, inner)
}

fn leaves(u: f32, v: f32, fp: f32, seed: u32) -> Rgb {
    let n1 = vnoise(u * 2.7, v * 2.7, seed ^ 0x55);
    let n2 = fbm(u, v, 5.0, 3, fp, seed ^ 0x99);
    let dark = (0.6 - n1).clamp(0.0, 0.6);
    let base: Rgb = if seed.is_multiple_of(3) { [95.0, 105.0, 45.0] } else { [60.0, 92.0, 48.0] };
    let c = scale(base, 1.0 + 0.55 * n2 - 0.9 * dark);
    add(c, 14.0 * grain(u, v, 0.04, fp, seed))
}

/// Signed "inside" measure of a sign plate shape; `u, v` centred, plate radius 0.35 m.
fn sign_shape(kind: u8, u: f32, v: f32) -> f32 {
    match kind {
        1 => {
            // Triangle, point up: inside all three edges.
            let e1 = v + 0.3;
            let e2 = 0.35 - v - 1.73 * u.abs() * 0.95;
            e1.min(e2)
        }
        2 => 0.33 - u.abs().max(v.abs()),
        _ => 0.35 - (u * u + v * v).sqrt(),
    }
}

fn sign(kind: u8, u: f32, v: f32, fp: f32) -> Rgb {
    let d = sign_shape(kind, u, v);
    let border = ((0.07 - d) / fp.max(1e-3) + 0.5).clamp(0.0, 1.0);
    match kind {
        0 => {
            let c = mix([240.0, 240.0, 235.0], [200.0, 30.0, 35.0], border);
            // Number in the middle.
            let t = text(u + 0.16, v + 0.1, 0.16, 0.2, fp, 1234);
            mix(c, [20.0, 20.0, 20.0], t)
        }
        1 => {
            let c = mix([240.0, 240.0, 235.0], [200.0, 30.0, 35.0], border);
            let sym = rect(u, v, -0.03, 0.03, -0.12, 0.1, fp);
            mix(c, [20.0, 20.0, 20.0], sym)
        }
        2 => {
            let c = mix([30.0, 80.0, 170.0], [240.0, 240.0, 240.0], border * 0.8);
            let sym = rect(u, v, -0.12, 0.12, -0.05, 0.05, fp)
                .max(rect(u, v, -0.05, 0.05, -0.2, 0.2, fp));
            mix(c, [245.0, 245.0, 245.0], sym)
        }
        _ => {
            let c: Rgb = [30.0, 80.0, 170.0];
            let arrow =
                rect(u - v, 0.0, -0.05, 0.05, -1.0, 1.0, fp) * rect(u, v, -0.2, 0.2, -0.2, 0.2, fp);
            let c = mix(c, [245.0, 245.0, 245.0], arrow);
            mix(c, [240.0, 240.0, 240.0], border * 0.5)
        }
    }
}

fn bike_shape(u: f32, v: f32) -> bool {
    // Two wheels (rings with spokes hint) and a frame of bars, 1.7 m long.
    let ring = |cx: f32| {
        let d = ((u - cx) * (u - cx) + (v - 0.34) * (v - 0.34)).sqrt();
        (d - 0.32).abs() < 0.035 || d < 0.05
    };
    let bar = |x0: f32, y0: f32, x1: f32, y1: f32| {
        let (dx, dy) = (x1 - x0, y1 - y0);
        let t = (((u - x0) * dx + (v - y0) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
        let (px, py) = (x0 + t * dx - u, y0 + t * dy - v);
        px * px + py * py < 0.03 * 0.03
    };
    ring(0.36)
        || ring(1.34)
        || bar(0.36, 0.34, 0.8, 0.36)
        || bar(0.8, 0.36, 0.7, 0.85)
        || bar(0.8, 0.36, 1.2, 0.8)
        || bar(0.7, 0.85, 1.2, 0.8)
        || bar(1.2, 0.8, 1.34, 0.34)
        || bar(1.2, 0.8, 1.18, 1.0)
        || bar(0.36, 0.34, 0.7, 0.85)
}

fn vehicle(paint: Rgb, part: VPart, dims: [f32; 2], seed: u32, u: f32, v: f32, fp: f32) -> Rgb {
    let w = dims[0];
    let y = v - dims[1];
    let glass: Rgb = [35.0, 42.0, 50.0];
    let refl = 40.0 * vnoise(u * 0.9, v * 2.0, seed ^ 3);
    let body = add(
        paint,
        8.0 * (vnoise(u * 2.0, v * 2.0, seed) - 0.5) * lod(2.0, fp)
            + 25.0 * (y - 0.3).clamp(0.0, 0.5),
    );
    match part {
        VPart::BodySide => {
            let mut c = body;
            // Sill, door seams, handles, a stripe of trim.
            c = mix(c, scale(paint, 0.45), rect(u, y, -1.0, w + 1.0, -1.0, 0.18, fp));
            for k in [0.36f32, 0.62] {
                c = mix(c, scale(paint, 0.3), line1(u - w * k, 0.02, fp));
                c = mix(
                    c,
                    [30.0, 30.0, 30.0],
                    rect(u, y, w * k - 0.35, w * k - 0.12, 0.55, 0.6, fp),
                );
            }
            mix(c, [50.0, 50.0, 52.0], rect(u, y, -1.0, w + 1.0, 0.38, 0.42, fp))
        }
        VPart::BodyFront | VPart::BodyBack => {
            let front = part == VPart::BodyFront;
            let mut c = body;
            let lamp: Rgb = if front { [235.0, 235.0, 225.0] } else { [190.0, 25.0, 25.0] };
            c = mix(c, lamp, rect(u, y, 0.08, 0.42, 0.45, 0.62, fp));
            c = mix(c, lamp, rect(u, y, w - 0.42, w - 0.08, 0.45, 0.62, fp));
            if front {
                let grille = rect(u, y, w * 0.5 - 0.4, w * 0.5 + 0.4, 0.28, 0.55, fp);
                let slats = 1.0 - 0.6 * lines(y, 0.05, 0.02, fp);
                c = mix(c, scale([40.0, 40.0, 42.0], slats), grille);
            }
            // Number plate with characters.
            let (px, py) = (w * 0.5 - 0.26, if front { 0.12 } else { 0.3 });
            let plate = rect(u, y, px, px + 0.52, py, py + 0.12, fp);
            let t = text(u - px - 0.04, y - py - 0.02, 0.062, 0.08, fp, seed);
            c = mix(c, mix([235.0, 235.0, 230.0], [15.0, 15.0, 15.0], t), plate);
            mix(c, [25.0, 25.0, 25.0], rect(u, y, -1.0, w + 1.0, -1.0, 0.1, fp))
        }
        VPart::CabinSide => {
            let pane = rect(u, y, 0.08, w - 0.08, 0.05, 0.42, fp);
            let pillar = line1(u - w * 0.5, 0.09, fp);
            let g = add(glass, refl);
            mix(body, g, pane * (1.0 - pillar))
        }
        VPart::CabinFront | VPart::CabinBack => {
            let pane = rect(u, y, 0.08, w - 0.08, 0.04, 0.42, fp);
            let mut g = add(glass, refl);
            if part == VPart::CabinBack {
                // Head rests silhouettes behind the rear window.
                let hr = rect(u, y, w * 0.2, w * 0.38, 0.05, 0.25, fp).max(rect(
                    u,
                    y,
                    w * 0.62,
                    w * 0.8,
                    0.05,
                    0.25,
                    fp,
                ));
                g = mix(g, [20.0, 20.0, 22.0], hr);
            }
            mix(body, g, pane)
        }
        VPart::Top => scale(body, 1.08),
        VPart::Wheel => {
            let r = dims[1].max(0.2);
            let c = 30.0 + 8.0 * grain(u, v, 0.02, fp, seed);
            let rim = disc(u, v, r, r, r * 0.55, fp);
            let hub = disc(u, v, r, r, r * 0.15, fp);
            let tyre: Rgb = [c, c, c];
            let m = mix(tyre, [150.0, 152.0, 155.0], rim);
            mix(m, [60.0, 60.0, 60.0], hub)
        }
        VPart::CargoSide => {
            // Corrugated panels with a logo and a text line.
            let groove = lines(u, 0.55, 0.05, fp);
            let mut c = scale(body, 1.0 - 0.25 * groove);
            let logo = rect(u, y, w * 0.15, w * 0.15 + 2.2, 1.2, 2.1, fp);
            let lc = pick(&[[200.0, 40.0, 30.0], [30.0, 60.0, 150.0], [20.0, 110.0, 60.0]], seed);
            c = mix(c, lc, logo);
            let t = text(u - w * 0.15 - 2.4, y - 1.35, 0.35, 0.6, fp, seed ^ 5);
            c = mix(c, [30.0, 30.0, 35.0], t);
            mix(c, [40.0, 40.0, 40.0], rect(u, y, -1.0, w + 1.0, -1.0, 0.12, fp))
        }
        VPart::CargoBack => {
            let mut c = body;
            // Two doors, locking bars, hinges, reflective chevrons, lights, plate.
            c = mix(c, scale(paint, 0.35), line1(u - w * 0.5, 0.03, fp));
            for k in [0.25f32, 0.75] {
                c = mix(c, [70.0, 72.0, 75.0], line1(u - w * k, 0.05, fp));
                for hy in [0.8f32, 1.6, 2.4] {
                    c = mix(
                        c,
                        [50.0, 50.0, 55.0],
                        rect(u, y, w * k - 0.1, w * k + 0.1, hy, hy + 0.08, fp),
                    );
                }
            }
            let chev = rect(u, y, 0.0, w, 0.0, 0.3, fp);
            if chev > 0.0 {
                let band = ifloor((u + y) / 0.2) & 1;
                let cc: Rgb = if band == 0 { [220.0, 40.0, 30.0] } else { [240.0, 240.0, 235.0] };
                c = mix(c, cc, chev);
            }
            c = mix(c, [190.0, 25.0, 25.0], rect(u, y, 0.05, 0.3, 0.32, 0.55, fp));
            c = mix(c, [190.0, 25.0, 25.0], rect(u, y, w - 0.3, w - 0.05, 0.32, 0.55, fp));
            let t = text(u - w * 0.3, y - 2.6, 0.22, 0.35, fp, seed ^ 9);
            c = mix(c, [30.0, 30.0, 35.0], t);
            let px = w * 0.5 - 0.26;
            let plate = rect(u, y, px, px + 0.52, 0.35, 0.47, fp);
            let tp = text(u - px - 0.04, y - 0.37, 0.062, 0.08, fp, seed);
            mix(c, mix([235.0, 235.0, 230.0], [15.0, 15.0, 15.0], tp), plate)
        }
    }
}

fn person(cloth: [Rgb; 2], part: PPart, seed: u32, u: f32, v: f32, fp: f32) -> Rgb {
    match part {
        PPart::Torso => {
            let folds = fbm(u, v, 4.0, 3, fp, seed);
            let mut c = add(cloth[0], 18.0 * folds);
            if seed.is_multiple_of(3) {
                c = mix(c, scale(cloth[0], 0.5), lines(v, 0.12, 0.05, fp));
            } else if seed % 3 == 1 {
                c = mix(c, [230.0, 230.0, 225.0], rect(u, v - 1.2, 0.12, 0.3, 0.1, 0.25, fp));
            }
            c
        }
        PPart::Legs => {
            let c = add(cloth[1], 14.0 * fbm(u, v, 5.0, 2, fp, seed ^ 2));
            mix(c, [30.0, 28.0, 26.0], rect(u, v, -1.0, 9.0, -1.0, 0.1, fp))
        }
        PPart::Head { front } => {
            let hair: Rgb =
                pick(&[[40.0, 30.0, 25.0], [120.0, 90.0, 50.0], [20.0, 20.0, 20.0]], seed);
            if front {
                let skin: Rgb = [200.0, 160.0, 130.0];
                let face = rect(u, v, 0.03, 0.19, -1.0, 1.62 + 0.14, fp);
                let c = mix(hair, skin, face);
                let eyes = disc(u, v, 0.07, 1.72, 0.015, fp).max(disc(u, v, 0.15, 1.72, 0.015, fp));
                mix(c, [30.0, 30.0, 30.0], eyes)
            } else {
                add(hair, 12.0 * grain(u, v, 0.02, fp, seed))
            }
        }
    }
}

/// Sky colour for a world-frame viewing direction `(x, y, z)` (y down), with soft clouds.
pub(crate) fn sky(dir: [f32; 3]) -> Rgb {
    let up = -dir[1] / (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    let t = up.clamp(0.0, 1.0);
    let horizon: Rgb = [222.0, 228.0, 235.0];
    let zenith: Rgb = [150.0, 180.0, 220.0];
    let mut c = mix(horizon, zenith, (t * 2.5).min(1.0));
    if up > 0.02 {
        let k = 1.0 / up;
        let (x, z) = (dir[0] * k * 0.004, dir[2] * k * 0.004);
        let cloud = vnoise(x * 6.0, z * 6.0, 91) * 0.6 + vnoise(x * 13.0, z * 13.0, 92) * 0.4;
        c = mix(c, [245.0, 245.0, 248.0], ((cloud - 0.45) * 2.5).clamp(0.0, 0.9));
    }
    c
}
