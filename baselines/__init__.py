"""Analytic solvers of the literature's problems and the policies built on them."""
