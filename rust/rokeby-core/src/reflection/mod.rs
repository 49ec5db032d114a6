//! Interactive reflection editing (Ritschel et al. 2009): the rotational factor of the polar
//! decomposition (`ortho`, eq. 5), regions of interest with smooth-step borders (§4, eq. 7) and the
//! MLS rotation field R(q) = ortho(Σ wₙ eₙ rₙᵀ), wₙ = 1/d² (eqs. 2–7).

pub mod field;
pub mod polar;
pub mod region;
