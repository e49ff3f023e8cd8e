//! How phases are given to a simulation: one per element, one per group of its elements, or (an
//! image's known phases) one per default group of the array. One rule, used by the simulation
//! and by the checks a caller makes against a scenario's [`crate::scenario::Outline`] before
//! building anything.

use crate::error::{require_finite, HasError, Result};

/// The number of groups G of an element → group map (its largest group number plus one; 0 for
/// no elements).
pub fn count(groups: &[usize]) -> usize {
    groups.iter().max().map_or(0, |m| m + 1)
}

/// An element-to-group map (element number = index), checked: every group from 0 to G-1 holds
/// at least one element. Returns G.
pub fn check_groups(groups: &[usize], n_elements: usize) -> Result<usize> {
    if groups.len() != n_elements {
        return Err(HasError::invalid("groups", format!("has {} entries for {} elements", groups.len(), n_elements)));
    }
    let n_groups = count(groups);
    let mut used = vec![false; n_groups];
    groups.iter().for_each(|&g| used[g] = true);
    if let Some(g) = used.iter().position(|u| !u) {
        return Err(HasError::invalid("groups", format!("group {g} has no element")));
    }
    Ok(n_groups)
}

/// `g` contiguous groups of `n_elements` by element number (`group = e·g / n`), as the paper's
/// quadrant array groups its 1024 elements into 16 of 64.
pub fn contiguous(n_elements: usize, g: usize) -> Result<Vec<usize>> {
    if g == 0 || g > n_elements {
        return Err(HasError::invalid("groups", format!("must be between 1 and {n_elements}, got {g}")));
    }
    Ok((0..n_elements).map(|e| e * g / n_elements).collect())
}

/// Phases (rad) added to the steering, one per element or one per group of `groups`, as one per
/// element; an error naming `name` otherwise.
pub fn per_element(name: &str, phases: &[f64], groups: &[usize], n_groups: usize) -> Result<Vec<f64>> {
    require_finite(name, phases)?;
    let n = groups.len();
    if phases.len() == n {
        Ok(phases.to_vec())
    } else if phases.len() == n_groups {
        Ok(groups.iter().map(|&g| phases[g]).collect())
    } else {
        Err(HasError::invalid(
            name,
            format!("has {} values; expected {} (one per element) or {} (one per group)", phases.len(), n, n_groups),
        ))
    }
}

/// An image's known phases (rad) as one per element: given per element, per group of `groups`,
/// or per default group of the array (`default_groups`: the paper's 16 groups of contiguous
/// element numbers, in which its diversity phases are written); empty = none. An error naming
/// `name` lists the lengths that would do.
pub fn known_per_element(name: &str, known: &[f64], groups: &[usize], n_groups: usize, default_groups: &[usize]) -> Result<Vec<f64>> {
    let n = groups.len();
    if known.is_empty() {
        return Ok(vec![0.0; n]);
    }
    require_finite(name, known)?;
    let n_default = count(default_groups);
    if known.len() == n_default && known.len() != n_groups && known.len() != n {
        return Ok(default_groups.iter().map(|&g| known[g]).collect());
    }
    per_element(name, known, groups, n_groups).map_err(|_| {
        let mut sizes = vec![format!("{n} (one per element)")];
        if n_groups != n {
            sizes.push(format!("{n_groups} (one per group)"));
        }
        if n_default != n_groups && n_default != n {
            sizes.push(format!("{n_default} (one per default group)"));
        }
        HasError::invalid(name, format!("has {} values; expected {}", known.len(), sizes.join(" or ")))
    })
}

/// Whether an element-to-group map gives each element its own group, in element order (a
/// per-element estimate).
pub fn one_per_element(groups: &[usize]) -> bool {
    groups.iter().enumerate().all(|(e, &g)| e == g)
}

/// How a prior's predicted phases (rad) are given.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PriorLayout {
    /// One per element.
    PerElement,
    /// One per group of the estimate's groups.
    PerGroup,
    /// One per default group of the array (as an image's known phases may be).
    PerDefaultGroup,
}

/// The layout of `len` predicted phases for an estimate on `groups` (G = `n_groups`): a
/// per-element estimate ([`one_per_element`]) takes them per element or per default group of
/// the array, as it takes an image's known phases ([`known_per_element`]); a group estimate per
/// element (each group then takes their circular mean) or per group. An error naming `name`
/// lists the lengths that would do. The one rule for the estimate and for the checks made
/// before building anything.
pub fn prior_layout(name: &str, len: usize, groups: &[usize], n_groups: usize, default_groups: &[usize]) -> Result<PriorLayout> {
    let n = groups.len();
    let per_element = one_per_element(groups);
    let (other, what) = if per_element { (count(default_groups), "default group") } else { (n_groups, "group") };
    // A group estimate reads a prior of G values per group, also where G = n (groups in another
    // order than the elements).
    if !per_element && len == n_groups {
        return Ok(PriorLayout::PerGroup);
    }
    if len == n {
        return Ok(PriorLayout::PerElement);
    }
    if len == other && len > 0 {
        return Ok(PriorLayout::PerDefaultGroup);
    }
    let mut sizes = format!("{n} (one per element)");
    if other != n {
        sizes += &format!(" or {other} (one per {what})");
    }
    Err(HasError::invalid(name, format!("has {len} values; expected {sizes}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_prior_is_laid_out_by_the_one_rule_of_its_estimate() {
        let default = contiguous(8, 2).unwrap();
        let elements: Vec<usize> = (0..8).collect();
        let four = contiguous(8, 4).unwrap();
        assert!(one_per_element(&elements) && !one_per_element(&four) && !one_per_element(&[1, 0]));
        assert_eq!(prior_layout("p", 8, &elements, 8, &default).unwrap(), PriorLayout::PerElement);
        assert_eq!(prior_layout("p", 2, &elements, 8, &default).unwrap(), PriorLayout::PerDefaultGroup);
        assert_eq!(prior_layout("p", 8, &four, 4, &default).unwrap(), PriorLayout::PerElement);
        assert_eq!(prior_layout("p", 4, &four, 4, &default).unwrap(), PriorLayout::PerGroup);
        let e = prior_layout("prior", 2, &four, 4, &default).unwrap_err().to_string();
        assert!(e.starts_with("prior: has 2 values; expected 8 (one per element) or 4 (one per group)"), "{e}");
        let e = prior_layout("prior", 4, &elements, 8, &default).unwrap_err().to_string();
        assert!(e.starts_with("prior: has 4 values; expected 8 (one per element) or 2 (one per default group)"), "{e}");
        // Groups in another order than the elements: G = n values are per group.
        let turned: Vec<usize> = (0..8).rev().collect();
        assert_eq!(prior_layout("p", 8, &turned, 8, &default).unwrap(), PriorLayout::PerGroup);
        // No values, or an array whose default groups are its elements: one size named.
        let e = prior_layout("prior", 0, &elements, 8, &default).unwrap_err().to_string();
        assert!(e.starts_with("prior: has 0 values; expected 8 (one per element) or 2"), "{e}");
        let e = prior_layout("prior", 3, &elements, 8, &elements).unwrap_err().to_string();
        assert_eq!(e, "prior: has 3 values; expected 8 (one per element)");
    }

    #[test]
    fn phases_per_group_expand_to_their_elements_and_wrong_lengths_are_named() {
        let groups = contiguous(8, 2).unwrap();
        assert_eq!(groups, vec![0, 0, 0, 0, 1, 1, 1, 1]);
        assert_eq!(per_element("p", &[1.0, 2.0], &groups, 2).unwrap(), vec![1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0]);
        assert_eq!(per_element("p", &[0.5; 8], &groups, 2).unwrap(), vec![0.5; 8]);
        let e = per_element("--correction", &[0.0; 3], &groups, 2).unwrap_err().to_string();
        assert!(e.starts_with("--correction: has 3 values; expected 8 (one per element) or 2 (one per group)"), "{e}");
        assert!(per_element("p", &[f64::NAN, 0.0], &groups, 2).unwrap_err().to_string().starts_with("p:"));
    }

    #[test]
    fn known_phases_may_come_per_default_group() {
        let groups = contiguous(8, 8).unwrap();
        let default = contiguous(8, 4).unwrap();
        assert_eq!(
            known_per_element("k", &[1.0, 2.0, 3.0, 4.0], &groups, 8, &default).unwrap(),
            vec![1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0]
        );
        assert_eq!(known_per_element("k", &[], &groups, 8, &default).unwrap(), vec![0.0; 8]);
        let e = known_per_element("k", &[0.0; 5], &groups, 8, &default).unwrap_err().to_string();
        assert!(e.contains("has 5 values; expected 8 (one per element) or 4 (one per default group)"), "{e}");
    }

    #[test]
    fn groups_must_cover_every_number_and_element() {
        assert_eq!(check_groups(&[0, 1, 1, 2], 4).unwrap(), 3);
        assert!(check_groups(&[0, 2, 2, 2], 4).unwrap_err().to_string().contains("group 1 has no element"));
        assert!(check_groups(&[0, 1], 4).is_err());
        assert!(contiguous(4, 0).is_err() && contiguous(4, 5).is_err());
    }
}
