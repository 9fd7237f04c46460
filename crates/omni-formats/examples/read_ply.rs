//! Times `omni_formats::ply::read_ply` on one file, for the side-by-side with Open3D's reader in
//! `scripts/bench_cloud.py`. Usage: `read_ply CLOUD.ply [REPEATS]`; prints
//! `{"points":N,"read_s":BEST}` (the best of REPEATS reads, default 3).

use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let path = PathBuf::from(args.get(1).ok_or("usage: read_ply CLOUD.ply [REPEATS]")?);
    let repeats: usize = args.get(2).map_or(Ok(3), |r| r.parse()).map_err(|e| format!("REPEATS: {e}"))?;
    let (mut best, mut points) = (f64::INFINITY, 0);
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let cloud = omni_formats::ply::read_ply(&path).map_err(|e| e.to_string())?;
        best = best.min(t.elapsed().as_secs_f64());
        points = cloud.len();
    }
    println!("{{\"points\":{points},\"read_s\":{best}}}");
    Ok(())
}
