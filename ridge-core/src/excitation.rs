//! Excitation signals (placeholder).
