#pragma once
// Sparse matrices with a pattern fixed once per scene. Values are written
// through precomputed slots (indices into valuePtr()), so assembly in the hot
// path never sorts triplets or allocates.

#include <Eigen/SparseCore>
#include <vector>

namespace stiffsim {

using SparseMatrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

// Collects the (row, col) positions of a pattern; duplicates are merged.
class PatternBuilder {
 public:
  PatternBuilder(int rows, int cols) : rows_(rows), cols_(cols) {}
  void add(int row, int col);
  // Every entry of a dense rows x cols block at (row0, col0).
  void add_block(int row0, int col0, int rows, int cols);
  // Every stored entry of `pattern`, shifted by (row0, col0).
  void add_pattern(const SparseMatrix& pattern, int row0 = 0, int col0 = 0);
  void add_diagonal(int first, int count);
  // A compressed matrix with explicit zeros in every position of the pattern.
  SparseMatrix build() const;
  int rows() const { return rows_; }
  int cols() const { return cols_; }

 private:
  int rows_, cols_;
  std::vector<std::pair<int, int>> entries_;  // (col, row), in the order added
};

// The pattern of dense b x b blocks, one in place of each entry of
// `blocks` (entry (I, J) becomes rows b I .. b I + b - 1 of columns b J ..
// b J + b - 1), with explicit zeros. Where a pattern is made of blocks
// (three velocities per particle), the blocks' pattern is built with
// b^2 times fewer entries to collect and sort.
SparseMatrix expand_blocks(const SparseMatrix& blocks, int b);

// Index into A.valuePtr() of entry (row, col); throws std::out_of_range if
// (row, col) is not in the pattern.
int slot_of(const SparseMatrix& A, int row, int col);

// For every stored entry k of `part` (in storage order), the slot of the same
// position in `whole`, shifted by (row0, col0). `part`'s pattern must be a
// subset of `whole`'s.
std::vector<int> slots_in(const SparseMatrix& whole, const SparseMatrix& part, int row0 = 0,
                          int col0 = 0);

// whole.valuePtr()[slots[k]] += scale * part.valuePtr()[k] for every k.
void scatter_add(const SparseMatrix& part, const std::vector<int>& slots, double scale,
                 SparseMatrix* whole);

// C = A B into C's existing pattern, which must hold the structural product
// (every position A B can reach); allocation-free once `marker` has
// A.rows() entries (the scratch that maps a row of C's column to its slot).
void multiply_into_pattern(const SparseMatrix& A, const SparseMatrix& B, SparseMatrix* C,
                           std::vector<int>* marker);

// Whether A and B store the same positions in the same order (values not
// compared): both compressed, of one size, with equal index arrays.
bool same_pattern(const SparseMatrix& A, const SparseMatrix& B);

// Whether `whole` stores every position `part` stores, and with
// with_diagonal every diagonal position too (square `whole`).
bool holds_pattern(const SparseMatrix& whole, const SparseMatrix& part, bool with_diagonal);

// True when A has the same pattern as its transpose (values not compared).
bool is_structurally_symmetric(const SparseMatrix& A);

// Zero every stored value, keeping the pattern.
inline void set_zero_keep_pattern(SparseMatrix* A) {
  std::fill(A->valuePtr(), A->valuePtr() + A->nonZeros(), 0.0);
}

}  // namespace stiffsim
