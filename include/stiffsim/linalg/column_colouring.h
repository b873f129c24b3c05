#pragma once
// Column colouring of a sparse Jacobian pattern (Curtis, Powell & Reid 1974):
// columns that share no nonzero row can be perturbed together, so one
// function evaluation per colour recovers every column of a coloured group.
// A chain or a cloth needs a number of colours set by the stencil, not by the
// number of unknowns.

#include <vector>

#include "stiffsim/linalg/sparse_pattern.h"

namespace stiffsim {

// One block of a larger pattern: its stored entries sit at (row0 + i, col0 + j)
// of the whole. Blocks may be empty (0 rows or columns) and may overlap.
struct PatternBlock {
  const SparseMatrix* pattern = nullptr;
  int row0 = 0;
  int col0 = 0;
};

struct ColumnColouring {
  // Colour of every column in [0, colours), or -1 for a column with no stored
  // entry in any block: it has nothing to difference and costs no evaluation.
  std::vector<int> colour;
  int colours = 0;
};

// Greedy distance-2 colouring of the columns of a rows x cols pattern made of
// `blocks` (e.g. the force Jacobian [dF/dq dF/dv dF/dz; dfz/dq dfz/dv dfz/dz]
// over x = (q, v, z)): two columns with a stored entry in the same row get
// different colours. Columns are visited in order and take the smallest colour
// free of conflicts, O(sum over rows of (row count)^2). The count lies between
// the most columns in one row and one plus the most columns one column meets:
// bounds set by the stencil, not the size. A band meets the lower bound; a
// cloth grid (stretch, shear, bend: lower bound 78 over (q, v)) lands about
// 35% above it and drifts up slowly with the rows' length (102 colours at
// 10x10, 108 at 60x60), the price of greedy against a lattice colouring
// (which systems that know their lattice provide instead:
// System::jacobian_colouring_hint).
// Throws std::invalid_argument if a block does not fit.
ColumnColouring colour_columns(int rows, int cols, const std::vector<PatternBlock>& blocks);

// The same for a single matrix.
ColumnColouring colour_columns(const SparseMatrix& pattern);

// True when `colouring` has one entry per column, every column with a stored
// entry has a colour in [0, colours), and no two columns of one colour share
// a row. For tests and debug checks.
bool is_valid_colouring(int rows, int cols, const std::vector<PatternBlock>& blocks,
                        const ColumnColouring& colouring);

}  // namespace stiffsim
