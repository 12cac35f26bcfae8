fn main() {
    let (w, h) = (1280, 800);
    println!("threads {}", rayon::current_num_threads());
    let t = makeit4d::stages::motion::bench_motion(w, h, 100, 10).unwrap();
    println!("{t:#?}");
    let b = makeit4d::render::blend::bench_blend(w, h, 10).unwrap();
    println!("blend {:.2} ms/frame", b * 1e3);
}
