// scratch, deleted after use
use has_core::has::RecordSpec;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;
use std::time::Instant;
fn cpu() -> f64 { let s = std::fs::read_to_string("/proc/self/stat").unwrap(); let f: Vec<&str> = s.rsplit(')').next().unwrap().split_whitespace().collect(); (f[11].parse::<f64>().unwrap() + f[12].parse::<f64>().unwrap()) / 100.0 }
fn main() {
    let sim = Simulation::new(&Scenario::default()).unwrap();
    let spec = RecordSpec { window: Some(sim.sampler.window.clone()), ..Default::default() };
    let small = { let mut w = sim.sampler.window.clone(); w.rows = 80..100; w.cols = 80..100; RecordSpec { window: Some(w), ..Default::default() } };
    let sources: Vec<Vec<C64>> = (0..sim.n_groups).map(|g| { let d: Vec<C64> = sim.steering.iter().zip(&sim.groups).map(|(&s, &k)| if k == g { C64::from_polar(1.0, s) } else { C64::new(0.0, 0.0) }).collect(); sim.source.field(&d).unwrap() }).collect();
    let one_thread = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let src = sim.source_field(&[]).unwrap();
    let fft = has_core::fft::Fft2::new(sim.grid.nx, sim.grid.ny);
    let (mut wss, mut wsp) = (fft.workspace(false), fft.workspace(true));
    let mut f = src.clone();
    let med = |v: &mut Vec<f64>| { v.sort_by(f64::total_cmp); format!("min {:.2} med {:.2}", v[0] * 1e3, v[v.len() / 2] * 1e3) };
    let (mut a, mut b, mut c) = (vec![], vec![], vec![]);
    for _ in 0..300 {
        let t = Instant::now(); fft.forward(&mut f, &mut wss); fft.inverse(&mut wss, &mut f); a.push(t.elapsed().as_secs_f64());
        let t = Instant::now(); fft.forward(&mut f, &mut wsp); fft.inverse(&mut wsp, &mut f); b.push(t.elapsed().as_secs_f64());
        let t = Instant::now(); rayon::scope(|_| { fft.forward(&mut f, &mut wsp); fft.inverse(&mut wsp, &mut f); }); c.push(t.elapsed().as_secs_f64());
        f.copy_from_slice(&src);
    }
    println!("fft pair ms: serial {} | parallel, ext thread {} | parallel, in pool {}", med(&mut a), med(&mut b), med(&mut c));
    let (mut p1, mut p2, mut p3) = (vec![], vec![], vec![]);
    for _ in 0..20 {
        let t = Instant::now(); sim.plan.propagate(&src, &spec).unwrap(); p1.push(t.elapsed().as_secs_f64());
        let t = Instant::now(); rayon::scope(|_| sim.plan.propagate(&src, &spec).unwrap()); p2.push(t.elapsed().as_secs_f64());
        let t = Instant::now(); one_thread.install(|| sim.plan.propagate(&src, &spec).unwrap()); p3.push(t.elapsed().as_secs_f64());
    }
    println!("one march to the slab ms: ext thread {} | in pool {} | 1-thread pool {}", med(&mut p1), med(&mut p2), med(&mut p3));
    for rep in 0..3 {
        let mut run = |name: &str, f: &dyn Fn()| { let (c, t) = (cpu(), Instant::now()); f(); println!("rep {rep} {name:45} wall {:.3} s cpu {:.2} s", t.elapsed().as_secs_f64(), cpu() - c); };
        run("batch (par_iter, serial fft)", &|| { sim.plan.propagate_batch(&sources, &spec).unwrap(); });
        run("batch, small window", &|| { sim.plan.propagate_batch(&sources, &small).unwrap(); });
        run("16 x propagate (parallel fft), ext thread", &|| { for s in &sources { sim.plan.propagate(s, &spec).unwrap(); } });
        run("16 x propagate (parallel fft), in pool", &|| rayon::scope(|_| { for s in &sources { sim.plan.propagate(s, &spec).unwrap(); } }));
        run("16 x propagate on a 1-thread pool", &|| one_thread.install(|| { for s in &sources { sim.plan.propagate(s, &spec).unwrap(); } }));
    }
}
