use sray_engine::nff::NffWriter;
use sray_engine::progress::NoProgress;
use sray_engine::spd::SpdScene;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene: SpdScene = args[1].parse().unwrap();
    let size: u32 = args[2].parse().unwrap();
    let out = std::io::BufWriter::new(std::io::stdout().lock());
    let mut w = NffWriter::new(out, "stdout");
    scene.generate(size, &mut w, &NoProgress).unwrap();
}
