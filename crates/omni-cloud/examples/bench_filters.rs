//! Times omniscan's cloud operations on a PLY file, for the side-by-side comparison with Open3D
//! in `scripts/bench_cloud.py` (which runs Open3D on the same file and parameters).
//!
//! Usage: `bench_filters CLOUD.ply OUT_DIR VOXELS K STD_RATIO NB_POINTS RADIUS`, VOXELS a
//! comma-separated list of voxel sizes (mm).
//! Prints one JSON object with the timings (s) and counts; writes `sor_mask.u8` and
//! `ror_mask.u8` (one byte per input point, 1 = kept), `voxel_<i>.ply` (i-th size, Open3D's grid
//! anchoring) and `written.ply` (PLY write timing) into OUT_DIR. Voxel downsampling (all cores
//! on fine grids, rayon) is timed three times, best kept, as wall time and as the CPU time of all
//! the process's threads (from /proc/self/task/*/schedstat: the work done, which other processes
//! on a busy machine do not inflate; on an idle machine wall ≈ CPU / threads).

use omni_cloud::filter::{radius_outlier_mask, statistical_outlier_mask, voxel_downsample, voxel_origin_open3d};
use omni_formats::ply::{Encoding, read_ply, write_ply};
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 8 {
        return Err("usage: bench_filters CLOUD.ply OUT_DIR VOXEL K STD_RATIO NB_POINTS RADIUS".into());
    }
    let num = |i: usize| args[i].parse::<f64>().map_err(|e| format!("argument {i}: {e}"));
    let voxels: Vec<f64> =
        args[3].split(',').map(|v| v.parse::<f64>().map_err(|e| format!("VOXELS: {e}"))).collect::<Result<_, _>>()?;
    let (k, ratio, nb, radius) = (num(4)? as usize, num(5)?, num(6)? as usize, num(7)?);
    let out = PathBuf::from(&args[2]);
    let t = Instant::now();
    let cloud = read_ply(&PathBuf::from(&args[1])).map_err(|e| e.to_string())?;
    let read_s = t.elapsed().as_secs_f64();

    let mut voxel_json = Vec::new();
    for (v, &voxel) in voxels.iter().enumerate() {
        let (mut wall, mut cpu, mut down) = (f64::INFINITY, f64::INFINITY, None);
        for _ in 0..3 {
            let (t, c) = (Instant::now(), process_cpu_s());
            let origin = voxel_origin_open3d(&cloud.positions, voxel);
            down = Some(voxel_downsample(&cloud, voxel, origin)?);
            wall = wall.min(t.elapsed().as_secs_f64());
            cpu = cpu.min(process_cpu_s() - c);
        }
        let down = down.ok_or("no voxel run")?;
        let count = down.len();
        write_ply(&out.join(format!("voxel_{v}.ply")), &down, Encoding::BinaryLittleEndian)
            .map_err(|e| e.to_string())?;
        voxel_json.push(format!("{{\"size\":{voxel},\"s\":{wall},\"cpu_s\":{cpu},\"count\":{count}}}"));
    }

    let t = Instant::now();
    let sor = statistical_outlier_mask(&cloud.positions, k, ratio)?;
    let sor_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let ror = radius_outlier_mask(&cloud.positions, nb, radius)?;
    let ror_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    write_ply(&out.join("written.ply"), &cloud, Encoding::BinaryLittleEndian).map_err(|e| e.to_string())?;
    let write_s = t.elapsed().as_secs_f64();

    let bytes = |m: &[bool]| m.iter().map(|&b| b as u8).collect::<Vec<u8>>();
    std::fs::write(out.join("sor_mask.u8"), bytes(&sor)).map_err(|e| e.to_string())?;
    std::fs::write(out.join("ror_mask.u8"), bytes(&ror)).map_err(|e| e.to_string())?;
    let kept = |m: &[bool]| m.iter().filter(|&&b| b).count();
    println!(
        "{{\"points\":{},\"threads\":{},\"read_s\":{read_s},\"voxel\":[{}],\"sor_s\":{sor_s},\"sor_kept\":{},\"ror_s\":{ror_s},\"ror_kept\":{},\"write_s\":{write_s}}}",
        cloud.len(),
        rayon::current_num_threads(),
        voxel_json.join(","),
        kept(&sor),
        kept(&ror)
    );
    Ok(())
}

/// CPU time of all the process's threads (s; rayon's workers included), or NaN where /proc
/// does not provide it.
fn process_cpu_s() -> f64 {
    let tasks = match std::fs::read_dir("/proc/self/task") {
        Ok(t) => t,
        Err(_) => return f64::NAN,
    };
    let mut ns = 0.0;
    for task in tasks {
        let stat = task.ok().and_then(|t| std::fs::read_to_string(t.path().join("schedstat")).ok());
        match stat.as_deref().and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok()) {
            Some(v) => ns += v,
            None => return f64::NAN,
        }
    }
    ns * 1e-9
}
