# SPDX-License-Identifier: GPL-3.0-or-later
"""Stage ``solve``: B = S + rho F B per colour band (Gauss-Seidel, Jacobi, progressive
refinement)."""
