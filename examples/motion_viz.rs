use makeit4d::progress::Progress;
use makeit4d::raster::Raster;
use makeit4d::stages::motion::*;

fn main() {
    for name in ["evening_glow_320", "cold_ripple_320", "forest_path_320", "starry_night_320"] {
        let path = format!("tests/data/{name}.jpg");
        let rgb = image::open(&path).unwrap().to_rgb32f();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        let img = Raster::from_vec(w, h, rgb.pixels().map(|p| p.0).collect()).unwrap();
        let t = std::time::Instant::now();
        let spec = suggest_motion(&img, None, None).unwrap();
        let field = flow_from_spec(&spec, w, h, &Progress::none()).unwrap();
        println!("{name}: {:?} regions {:?} arrows {:?} json {} bytes, ignored {:?}", t.elapsed(),
            spec.regions.iter().map(|r| (&r.name, r.strokes.len())).collect::<Vec<_>>(),
            spec.regions.iter().map(|r| r.arrows.iter().map(|a| (a.start, a.end, a.speed)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            serde_json::to_string(&spec).unwrap().len(), field.ignored_arrows);
        let masks: Vec<_> = spec.regions.iter().map(|r| rasterise_strokes(&r.strokes, w, h)).collect();
        let mut out = image::RgbImage::new(w as u32 * 2, h as u32);
        let maxv = field.flow.data().iter().map(|v| v[0].abs().max(v[1].abs())).fold(1e-6f32, f32::max);
        for y in 0..h { for x in 0..w {
            let mut c = img.at(x, y);
            for (i, m) in masks.iter().enumerate() {
                let tint = if spec.regions[i].name == "sky" { [0.0, 0.0, 1.0] } else { [0.0, 1.0, 0.0] };
                let a = m.at(x, y) * 0.5;
                for k in 0..3 { c[k] = c[k] * (1.0 - a) + tint[k] * a; }
            }
            out.put_pixel(x as u32, y as u32, image::Rgb(c.map(|v| (v.clamp(0.0,1.0) * 255.0) as u8)));
            let v = field.flow.at(x, y);
            let f = [0.5 + 0.5 * v[0] / maxv, 0.5 + 0.5 * v[1] / maxv, if v == [0.0,0.0] {0.0} else {0.5}];
            out.put_pixel((w + x) as u32, y as u32, image::Rgb(f.map(|v| (v.clamp(0.0,1.0) * 255.0) as u8)));
        }}
        for r in &spec.regions { for a in &r.arrows {
            for s in 0..=50 { let t = s as f32 / 50.0;
                let x = a.start[0] + t * (a.end[0] - a.start[0]); let y = a.start[1] + t * (a.end[1] - a.start[1]);
                if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h { out.put_pixel(x as u32, y as u32, image::Rgb([255, 0, 0])); }
            }
            out.put_pixel(a.end[0] as u32, a.end[1] as u32, image::Rgb([255,255,0]));
        }}
        out.save(format!("/tmp/motionviz/{name}_suggest.png")).unwrap();
    }
}
