#include "stiffsim/linalg/sparse_pattern.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace stiffsim {
namespace {

std::string position(int row, int col) {
  return "(" + std::to_string(row) + ", " + std::to_string(col) + ")";
}

// Storage range [begin, end) of column `col`; handles uncompressed matrices
// too so that helpers never silently read stale entries.
std::pair<int, int> column_range(const SparseMatrix& A, int col) {
  const int begin = A.outerIndexPtr()[col];
  const int end = A.isCompressed() ? A.outerIndexPtr()[col + 1] : begin + A.innerNonZeroPtr()[col];
  return {begin, end};
}

// Slot of `row` in column `col`, or -1. Row indices are sorted within a column
// (Eigen keeps them sorted, and build() does too), so binary search applies.
int find_slot(const SparseMatrix& A, int row, int col) {
  const auto [begin, end] = column_range(A, col);
  const int* first = A.innerIndexPtr() + begin;
  const int* last = A.innerIndexPtr() + end;
  const int* it = std::lower_bound(first, last, row);
  if (it == last || *it != row) return -1;
  return static_cast<int>(it - A.innerIndexPtr());
}

}  // namespace

void PatternBuilder::add(int row, int col) {
  if (row < 0 || row >= rows_ || col < 0 || col >= cols_) {
    throw std::out_of_range("PatternBuilder::add: entry " + position(row, col) + " outside a " +
                            std::to_string(rows_) + " x " + std::to_string(cols_) + " pattern");
  }
  entries_.emplace_back(col, row);
}

void PatternBuilder::add_block(int row0, int col0, int rows, int cols) {
  if (rows < 0 || cols < 0) {
    throw std::invalid_argument("PatternBuilder::add_block: negative block size " +
                                std::to_string(rows) + " x " + std::to_string(cols));
  }
  for (int j = 0; j < cols; ++j) {
    for (int i = 0; i < rows; ++i) add(row0 + i, col0 + j);
  }
}

void PatternBuilder::add_pattern(const SparseMatrix& pattern, int row0, int col0) {
  // Reserved ahead, keeping the vector's geometric growth: on the 100x100
  // sheet the Jacobians' union adds 1.2 M entries a pattern, and growing
  // by doubling moved and page-faulted each copy again.
  const std::size_t needed = entries_.size() + static_cast<std::size_t>(pattern.nonZeros());
  if (needed > entries_.capacity()) entries_.reserve(std::max(needed, 2 * entries_.capacity()));
  for (int j = 0; j < pattern.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(pattern, j); it; ++it) {
      add(row0 + it.row(), col0 + it.col());
    }
  }
}

void PatternBuilder::add_diagonal(int first, int count) {
  if (count < 0) {
    throw std::invalid_argument("PatternBuilder::add_diagonal: negative count " +
                                std::to_string(count));
  }
  for (int k = first; k < first + count; ++k) add(k, k);
}

SparseMatrix PatternBuilder::build() const {
  // A counting sort by column, then each column's rows sorted and made
  // unique: linear in the entries but for the short per-column sorts, where
  // one sort of all (col, row) pairs took 25 ms of a 32x32 cloth's set-up
  // (its springs add each block entry once per spring, 0.2 M pairs).
  std::vector<int> start(cols_ + 1, 0);
  for (const auto& [col, row] : entries_) ++start[col + 1];
  for (int j = 0; j < cols_; ++j) start[j + 1] += start[j];
  std::vector<int> rows(entries_.size());
  {
    std::vector<int> next(start.begin(), start.end() - 1);
    for (const auto& [col, row] : entries_) rows[next[col]++] = row;
  }
  SparseMatrix A(rows_, cols_);
  int* outer = A.outerIndexPtr();
  outer[0] = 0;
  std::size_t kept = 0;
  for (int j = 0; j < cols_; ++j) {
    const auto first = rows.begin() + start[j], last = rows.begin() + start[j + 1];
    std::sort(first, last);
    const auto end = std::unique(first, last);
    // Compacted in place: a column's unique rows move down, never past
    // their own.
    for (auto it = first; it != end; ++it) rows[kept++] = *it;
    outer[j + 1] = static_cast<int>(kept);
  }
  A.resizeNonZeros(static_cast<Eigen::Index>(kept));
  std::copy_n(rows.begin(), kept, A.innerIndexPtr());
  std::fill(A.valuePtr(), A.valuePtr() + kept, 0.0);
  return A;
}

SparseMatrix expand_blocks(const SparseMatrix& blocks, int b) {
  if (b < 1) throw std::invalid_argument("expand_blocks: block size " + std::to_string(b));
  const int cols = static_cast<int>(blocks.cols());
  SparseMatrix A(b * blocks.rows(), b * cols);
  A.resizeNonZeros(static_cast<Eigen::Index>(b) * b * blocks.nonZeros());
  int* outer = A.outerIndexPtr();
  int* inner = A.innerIndexPtr();
  int k = 0;
  outer[0] = 0;
  for (int J = 0; J < cols; ++J) {
    const auto [begin, end] = column_range(blocks, J);
    for (int c = 0; c < b; ++c) {
      // The block rows are sorted, so the expanded rows are too.
      for (int s = begin; s < end; ++s) {
        const int I = blocks.innerIndexPtr()[s];
        for (int r = 0; r < b; ++r) inner[k++] = b * I + r;
      }
      outer[b * J + c + 1] = k;
    }
  }
  set_zero_keep_pattern(&A);
  return A;
}

int slot_of(const SparseMatrix& A, int row, int col) {
  const int slot =
      (row >= 0 && row < A.rows() && col >= 0 && col < A.cols()) ? find_slot(A, row, col) : -1;
  if (slot < 0) {
    throw std::out_of_range("slot_of: entry " + position(row, col) + " is not in the " +
                            std::to_string(A.rows()) + " x " + std::to_string(A.cols()) +
                            " pattern");
  }
  return slot;
}

std::vector<int> slots_in(const SparseMatrix& whole, const SparseMatrix& part, int row0, int col0) {
  if (row0 < 0 || col0 < 0 || row0 + part.rows() > whole.rows() ||
      col0 + part.cols() > whole.cols()) {
    throw std::invalid_argument("slots_in: a " + std::to_string(part.rows()) + " x " +
                                std::to_string(part.cols()) + " part at " + position(row0, col0) +
                                " does not fit in a " + std::to_string(whole.rows()) + " x " +
                                std::to_string(whole.cols()) + " matrix");
  }
  std::vector<int> slots;
  slots.reserve(static_cast<std::size_t>(part.nonZeros()));
  for (int j = 0; j < part.outerSize(); ++j) {
    // Both columns are sorted, so one merge walk finds every slot.
    auto [w, w_end] = column_range(whole, col0 + j);
    for (SparseMatrix::InnerIterator it(part, j); it; ++it) {
      const int row = row0 + it.row();
      while (w < w_end && whole.innerIndexPtr()[w] < row) ++w;
      if (w == w_end || whole.innerIndexPtr()[w] != row) {
        throw std::invalid_argument("slots_in: entry " + position(it.row(), it.col()) +
                                    " of the part (" + position(row, col0 + j) +
                                    " of the whole) is missing from the whole pattern");
      }
      slots.push_back(w);
    }
  }
  return slots;
}

void scatter_add(const SparseMatrix& part, const std::vector<int>& slots, double scale,
                 SparseMatrix* whole) {
  // Only the cheap size check: this runs in the hot path, and slots come from
  // slots_in(), which has validated every position already.
  if (static_cast<Eigen::Index>(slots.size()) != part.nonZeros() || !part.isCompressed()) {
    throw std::invalid_argument("scatter_add: " + std::to_string(slots.size()) +
                                " slots for a compressed part with " +
                                std::to_string(part.nonZeros()) + " stored entries required");
  }
  const double* values = part.valuePtr();
  double* target = whole->valuePtr();
  const std::size_t count = slots.size();
  for (std::size_t k = 0; k < count; ++k) target[slots[k]] += scale * values[k];
}

bool same_pattern(const SparseMatrix& A, const SparseMatrix& B) {
  if (A.rows() != B.rows() || A.cols() != B.cols() || !A.isCompressed() || !B.isCompressed() ||
      A.nonZeros() != B.nonZeros()) {
    return false;
  }
  return std::equal(A.outerIndexPtr(), A.outerIndexPtr() + A.outerSize() + 1, B.outerIndexPtr()) &&
         std::equal(A.innerIndexPtr(), A.innerIndexPtr() + A.nonZeros(), B.innerIndexPtr());
}

bool holds_pattern(const SparseMatrix& whole, const SparseMatrix& part, bool with_diagonal) {
  if (part.rows() > whole.rows() || part.cols() > whole.cols()) return false;
  if (with_diagonal) {
    if (whole.rows() != whole.cols()) return false;
    for (int j = 0; j < whole.cols(); ++j) {
      if (find_slot(whole, j, j) < 0) return false;
    }
  }
  for (int j = 0; j < part.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(part, j); it; ++it) {
      if (find_slot(whole, static_cast<int>(it.row()), j) < 0) return false;
    }
  }
  return true;
}

bool is_structurally_symmetric(const SparseMatrix& A) {
  if (A.rows() != A.cols()) return false;
  for (int j = 0; j < A.outerSize(); ++j) {
    for (SparseMatrix::InnerIterator it(A, j); it; ++it) {
      if (find_slot(A, j, static_cast<int>(it.row())) < 0) return false;
    }
  }
  return true;
}

void multiply_into_pattern(const SparseMatrix& A, const SparseMatrix& B, SparseMatrix* C,
                           std::vector<int>* marker) {
  if (A.cols() != B.rows() || C->rows() != A.rows() || C->cols() != B.cols()) {
    throw std::invalid_argument("multiply_into_pattern: sizes do not match");
  }
  // The marker is all -1 between columns.
  if (static_cast<Eigen::Index>(marker->size()) != A.rows()) marker->assign(A.rows(), -1);
  double* out = C->valuePtr();
  for (int j = 0; j < B.outerSize(); ++j) {
    const int begin = C->outerIndexPtr()[j];
    for (int k = begin; k < C->outerIndexPtr()[j + 1]; ++k) {
      (*marker)[C->innerIndexPtr()[k]] = k;
      out[k] = 0.0;
    }
    for (SparseMatrix::InnerIterator b(B, j); b; ++b) {
      for (SparseMatrix::InnerIterator a(A, b.row()); a; ++a) {
        const int slot = (*marker)[a.row()];
        if (slot < 0) {
          for (int k = begin; k < C->outerIndexPtr()[j + 1]; ++k) (*marker)[C->innerIndexPtr()[k]] = -1;
          throw std::invalid_argument("multiply_into_pattern: the product reaches (" +
                                      std::to_string(a.row()) + ", " + std::to_string(j) +
                                      "), outside C's pattern");
        }
        out[slot] += a.value() * b.value();
      }
    }
    for (int k = begin; k < C->outerIndexPtr()[j + 1]; ++k) (*marker)[C->innerIndexPtr()[k]] = -1;
  }
}

}  // namespace stiffsim
