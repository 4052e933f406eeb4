//! GA-PSO: particle swarm optimisation with genetic operators (seed 001 §3,
//! Fig. 2), a bounded global minimiser for the Bouc-Wen identification.
//!
//! Seed 001 names the hybrid and draws its flow chart (Fig. 2) but prints no
//! operator or setting, so this module fixes one common form of it:
//!
//! 1. The swarm is scattered over the box by Latin-hypercube sampling (every
//!    dimension's range cut into `population` strata, one particle per
//!    stratum), which covers the box far better than independent draws.
//! 2. Every generation evaluates all particles in parallel (rayon), then
//!    updates the personal bests and the swarm's best.
//! 3. GA step: the worst `replaced_fraction` of the swarm (ranked by their
//!    current fitness) is replaced by children of personal bests chosen by
//!    binary tournament: blend crossover (BLX-0.25, so a child can land a
//!    little outside its parents' segment) and Gaussian mutation of each gene
//!    with probability `mutation_probability`, its width shrinking from 10 %
//!    of the range to 1 % over the run. Children start with zero velocity
//!    and their own position as personal best.
//! 4. PSO step for the others: v ← w·v + c1·r1·(pbest − x) + c2·r2·(gbest − x),
//!    with the inertia w falling linearly from `inertia.0` to `inertia.1`,
//!    |v| limited to `max_velocity_fraction` of the range, and a particle
//!    leaving the box stopped at its wall with its velocity reversed there.
//!
//! Every random number comes from one Xoshiro256++ stream drawn in a fixed
//! order on the calling thread; only the (pure) fitness evaluations run in
//! parallel. The result is therefore the same for a given seed on any number
//! of threads.

use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Settings of the GA-PSO search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaPsoOptions {
    /// Particles in the swarm.
    pub population: usize,
    /// Generations at most.
    pub generations: usize,
    /// Stop when the best fitness has not improved by a relative
    /// `stall_tolerance` for this many generations.
    pub stall_generations: usize,
    pub stall_tolerance: f64,
    /// Seed of the random stream.
    pub seed: u64,
    /// Inertia weight at the first and the last generation.
    pub inertia: (f64, f64),
    /// Cognitive (personal-best) and social (swarm-best) acceleration.
    pub cognitive: f64,
    pub social: f64,
    /// Largest speed per generation, as a fraction of each dimension's range.
    pub max_velocity_fraction: f64,
    /// Fraction of the swarm replaced by GA children every generation.
    pub replaced_fraction: f64,
    /// Probability that a child's gene is mutated.
    pub mutation_probability: f64,
}

impl Default for GaPsoOptions {
    /// Settings that find the Bouc-Wen optimum of this crate's tests and data
    /// reliably (constriction-equivalent c1 = c2 = 1.49445 of Clerc and
    /// Kennedy, inertia 0.9 → 0.4 of Shi and Eberhart).
    fn default() -> Self {
        GaPsoOptions {
            population: 40,
            generations: 150,
            stall_generations: 30,
            stall_tolerance: 1e-6,
            seed: 0,
            inertia: (0.9, 0.4),
            cognitive: 1.494_45,
            social: 1.494_45,
            max_velocity_fraction: 0.2,
            replaced_fraction: 0.25,
            mutation_probability: 0.1,
        }
    }
}

/// A box [lower_i, upper_i] per dimension.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
}

/// Why a search cannot start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GaPsoError {
    #[error("bounds: lower has {lower} entries, upper {upper}; give one pair per parameter")]
    BoundsLength { lower: usize, upper: usize },
    #[error("bounds of parameter {index}: [{lower}, {upper}] is not a finite, non-empty interval")]
    BoundsInterval {
        index: usize,
        lower: f64,
        upper: f64,
    },
    #[error("GA-PSO needs a population of at least 4 and at least one generation")]
    Settings,
}

impl Bounds {
    fn check(&self) -> Result<(), GaPsoError> {
        if self.lower.len() != self.upper.len() || self.lower.is_empty() {
            return Err(GaPsoError::BoundsLength {
                lower: self.lower.len(),
                upper: self.upper.len(),
            });
        }
        for (index, (&lower, &upper)) in self.lower.iter().zip(&self.upper).enumerate() {
            if !(lower.is_finite() && upper.is_finite() && lower < upper) {
                return Err(GaPsoError::BoundsInterval {
                    index,
                    lower,
                    upper,
                });
            }
        }
        Ok(())
    }

    fn range(&self, i: usize) -> f64 {
        self.upper[i] - self.lower[i]
    }

    /// Whether every coordinate of `point` lies in its interval.
    pub fn contains(&self, point: &[f64]) -> bool {
        point
            .iter()
            .zip(self.lower.iter().zip(&self.upper))
            .all(|(v, (lo, hi))| *lo <= *v && *v <= *hi)
    }

    /// `point` with every coordinate moved into its interval.
    pub fn clamp(&self, point: &[f64]) -> Vec<f64> {
        point
            .iter()
            .zip(self.lower.iter().zip(&self.upper))
            .map(|(v, (lo, hi))| v.clamp(*lo, *hi))
            .collect()
    }
}

/// The outcome of a search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaPsoResult {
    /// The best point found.
    pub best: Vec<f64>,
    /// Its fitness.
    pub fitness: f64,
    /// The best fitness after each generation.
    pub history: Vec<f64>,
    /// Fitness evaluations made.
    pub evaluations: usize,
}

struct Particle {
    position: Vec<f64>,
    velocity: Vec<f64>,
    fitness: f64,
    best_position: Vec<f64>,
    best_fitness: f64,
}

/// Minimises `fitness` over `bounds` (module comment). A non-finite fitness
/// counts as worse than any finite one. `progress(generation, best)` is
/// called after every generation, on the calling thread.
pub fn minimize<F>(
    fitness: F,
    bounds: &Bounds,
    options: &GaPsoOptions,
    mut progress: impl FnMut(usize, f64),
) -> Result<GaPsoResult, GaPsoError>
where
    F: Fn(&[f64]) -> f64 + Sync,
{
    bounds.check()?;
    if options.population < 4 || options.generations == 0 {
        return Err(GaPsoError::Settings);
    }
    let dimensions = bounds.lower.len();
    let population = options.population;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(options.seed);
    let finite_or_worst = |f: f64| if f.is_finite() { f } else { f64::INFINITY };

    let mut swarm: Vec<Particle> = latin_hypercube(bounds, population, &mut rng)
        .into_iter()
        .map(|position| Particle {
            velocity: vec![0.0; dimensions],
            best_position: position.clone(),
            position,
            fitness: f64::INFINITY,
            best_fitness: f64::INFINITY,
        })
        .collect();
    let mut best_position = swarm[0].position.clone();
    let mut best_fitness = f64::INFINITY;
    let mut history = Vec::with_capacity(options.generations);
    let mut evaluations = 0;
    let mut stalled = 0;

    for generation in 0..options.generations {
        let values: Vec<f64> = swarm
            .par_iter()
            .map(|p| finite_or_worst(fitness(&p.position)))
            .collect();
        evaluations += values.len();
        let previous_best = best_fitness;
        for (particle, value) in swarm.iter_mut().zip(values) {
            particle.fitness = value;
            if value < particle.best_fitness {
                particle.best_fitness = value;
                particle.best_position.clone_from(&particle.position);
            }
            if value < best_fitness {
                best_fitness = value;
                best_position.clone_from(&particle.position);
            }
        }
        history.push(best_fitness);
        progress(generation, best_fitness);

        let improved = previous_best.is_infinite()
            || previous_best - best_fitness > options.stall_tolerance * previous_best.abs();
        stalled = if improved { 0 } else { stalled + 1 };
        if stalled >= options.stall_generations || generation + 1 == options.generations {
            break;
        }

        let progress_fraction = generation as f64 / (options.generations - 1).max(1) as f64;
        genetic_step(&mut swarm, bounds, options, progress_fraction, &mut rng);
        swarm_step(
            &mut swarm,
            &best_position,
            bounds,
            options,
            progress_fraction,
            &mut rng,
        );
    }
    Ok(GaPsoResult {
        best: best_position,
        fitness: best_fitness,
        history,
        evaluations,
    })
}

/// One point per stratum of every dimension, strata paired at random.
fn latin_hypercube(bounds: &Bounds, count: usize, rng: &mut Xoshiro256PlusPlus) -> Vec<Vec<f64>> {
    let dimensions = bounds.lower.len();
    let mut points = vec![vec![0.0; dimensions]; count];
    for d in 0..dimensions {
        let mut strata: Vec<usize> = (0..count).collect();
        // Fisher-Yates, drawn from the one stream.
        for i in (1..count).rev() {
            let j = rng.random_range(0..=i);
            strata.swap(i, j);
        }
        for (point, stratum) in points.iter_mut().zip(strata) {
            let fraction = (stratum as f64 + rng.random_range(0.0..1.0)) / count as f64;
            point[d] = bounds.lower[d] + fraction * bounds.range(d);
        }
    }
    points
}

/// Replaces the worst particles by tournament-selected, crossed and mutated
/// children of personal bests (module comment, step 3).
fn genetic_step(
    swarm: &mut [Particle],
    bounds: &Bounds,
    options: &GaPsoOptions,
    progress_fraction: f64,
    rng: &mut Xoshiro256PlusPlus,
) {
    let population = swarm.len();
    let replaced = ((population as f64 * options.replaced_fraction).round() as usize)
        .min(population.saturating_sub(2));
    if replaced == 0 {
        return;
    }
    let mut ranking: Vec<usize> = (0..population).collect();
    // Stable sort on the current fitness; ties keep index order.
    ranking.sort_by(|&a, &b| swarm[a].fitness.total_cmp(&swarm[b].fitness));
    let survivors = &ranking[..population - replaced];
    let mutation_width = 0.1 - 0.09 * progress_fraction;

    let mut children = Vec::with_capacity(replaced);
    for _ in 0..replaced {
        let mut tournament = || {
            let a = survivors[rng.random_range(0..survivors.len())];
            let b = survivors[rng.random_range(0..survivors.len())];
            if swarm[a].best_fitness <= swarm[b].best_fitness {
                a
            } else {
                b
            }
        };
        let (mother, father) = (tournament(), tournament());
        let mut child = Vec::with_capacity(bounds.lower.len());
        for d in 0..bounds.lower.len() {
            let (m, f) = (
                swarm[mother].best_position[d],
                swarm[father].best_position[d],
            );
            let blend = rng.random_range(-0.25..1.25);
            let mut gene = m + blend * (f - m);
            if rng.random_range(0.0..1.0) < options.mutation_probability {
                let normal: f64 = StandardNormal.sample(rng);
                gene += normal * mutation_width * bounds.range(d);
            }
            child.push(gene.clamp(bounds.lower[d], bounds.upper[d]));
        }
        children.push(child);
    }
    for (&index, child) in ranking[population - replaced..].iter().zip(children) {
        let particle = &mut swarm[index];
        particle.velocity.iter_mut().for_each(|v| *v = 0.0);
        particle.best_position.clone_from(&child);
        particle.best_fitness = f64::INFINITY;
        particle.position = child;
        particle.fitness = f64::INFINITY;
    }
}

/// Velocity and position update of the particles (module comment, step 4);
/// children of this generation (zero velocity, no fitness yet) move too.
fn swarm_step(
    swarm: &mut [Particle],
    best_position: &[f64],
    bounds: &Bounds,
    options: &GaPsoOptions,
    progress_fraction: f64,
    rng: &mut Xoshiro256PlusPlus,
) {
    let inertia = options.inertia.0 + (options.inertia.1 - options.inertia.0) * progress_fraction;
    for particle in swarm.iter_mut() {
        for (d, &global_best) in best_position.iter().enumerate() {
            let limit = options.max_velocity_fraction * bounds.range(d);
            let r1 = rng.random_range(0.0..1.0);
            let r2 = rng.random_range(0.0..1.0);
            let x = particle.position[d];
            let v = inertia * particle.velocity[d]
                + options.cognitive * r1 * (particle.best_position[d] - x)
                + options.social * r2 * (global_best - x);
            let mut v = v.clamp(-limit, limit);
            let mut moved = x + v;
            if moved < bounds.lower[d] {
                moved = bounds.lower[d];
                v = -v;
            } else if moved > bounds.upper[d] {
                moved = bounds.upper[d];
                v = -v;
            }
            particle.position[d] = moved;
            particle.velocity[d] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rastrigin(x: &[f64]) -> f64 {
        10.0 * x.len() as f64
            + x.iter()
                .map(|v| v * v - 10.0 * (2.0 * std::f64::consts::PI * v).cos())
                .sum::<f64>()
    }

    fn square_bounds(n: usize, half: f64) -> Bounds {
        Bounds {
            lower: vec![-half; n],
            upper: vec![half; n],
        }
    }

    /// Rastrigin has ~10^4 local minima in this box; a pure local search
    /// from a random start ends in one of them almost surely.
    #[test]
    fn finds_the_global_minimum_of_a_multimodal_function() {
        let options = GaPsoOptions {
            generations: 400,
            stall_generations: 100,
            ..GaPsoOptions::default()
        };
        let result = minimize(rastrigin, &square_bounds(4, 5.12), &options, |_, _| {}).unwrap();
        assert!(result.fitness < 1e-6, "fitness {}", result.fitness);
        for x in &result.best {
            assert!(x.abs() < 1e-3, "best {:?}", result.best);
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_result_and_another_seed_another_path() {
        let options = GaPsoOptions {
            generations: 40,
            ..GaPsoOptions::default()
        };
        let bounds = square_bounds(3, 5.12);
        let a = minimize(rastrigin, &bounds, &options, |_, _| {}).unwrap();
        let b = minimize(rastrigin, &bounds, &options, |_, _| {}).unwrap();
        assert_eq!(a, b);
        let other = GaPsoOptions { seed: 1, ..options };
        let c = minimize(rastrigin, &bounds, &other, |_, _| {}).unwrap();
        assert_ne!(a.history, c.history);
    }

    #[test]
    fn the_best_stays_inside_the_bounds_and_history_never_rises() {
        // The unconstrained minimum (x = 10) lies outside the box.
        let bounds = Bounds {
            lower: vec![-1.0, -1.0],
            upper: vec![2.0, 2.0],
        };
        let f = |x: &[f64]| (x[0] - 10.0).powi(2) + x[1] * x[1];
        let result = minimize(f, &bounds, &GaPsoOptions::default(), |_, _| {}).unwrap();
        assert!((result.best[0] - 2.0).abs() < 1e-6, "{:?}", result.best);
        assert!(result.history.windows(2).all(|w| w[1] <= w[0]));
    }

    #[test]
    fn refuses_bad_bounds_and_settings() {
        let f = |x: &[f64]| x[0];
        let empty = Bounds {
            lower: vec![1.0],
            upper: vec![1.0],
        };
        assert!(matches!(
            minimize(f, &empty, &GaPsoOptions::default(), |_, _| {}),
            Err(GaPsoError::BoundsInterval { index: 0, .. })
        ));
        let ragged = Bounds {
            lower: vec![0.0, 0.0],
            upper: vec![1.0],
        };
        assert!(matches!(
            minimize(f, &ragged, &GaPsoOptions::default(), |_, _| {}),
            Err(GaPsoError::BoundsLength { .. })
        ));
        let tiny = GaPsoOptions {
            population: 2,
            ..GaPsoOptions::default()
        };
        assert_eq!(
            minimize(f, &square_bounds(1, 1.0), &tiny, |_, _| {}),
            Err(GaPsoError::Settings)
        );
    }

    #[test]
    fn a_non_finite_fitness_is_avoided() {
        let f = |x: &[f64]| {
            if x[0] < 0.0 {
                f64::NAN
            } else {
                (x[0] - 0.5).powi(2)
            }
        };
        let result = minimize(
            f,
            &square_bounds(1, 1.0),
            &GaPsoOptions::default(),
            |_, _| {},
        )
        .unwrap();
        assert!((result.best[0] - 0.5).abs() < 1e-4);
    }
}
