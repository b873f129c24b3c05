#include "stiffsim/linalg/column_colouring.h"

#include <stdexcept>
#include <string>

namespace stiffsim {
namespace {

// The whole pattern both ways: the rows of every column and the columns of
// every row (overlapping blocks may repeat an entry; the colouring does not
// mind).
struct Adjacency {
  std::vector<int> col_start, col_rows;  // CSC
  std::vector<int> row_start, row_cols;  // CSR
};

Adjacency adjacency(int rows, int cols, const std::vector<PatternBlock>& blocks) {
  if (rows < 0 || cols < 0) {
    throw std::invalid_argument("colour_columns: negative size " + std::to_string(rows) + " x " +
                                std::to_string(cols));
  }
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const PatternBlock& block = blocks[b];
    if (block.pattern == nullptr || block.row0 < 0 || block.col0 < 0 ||
        block.row0 + block.pattern->rows() > rows || block.col0 + block.pattern->cols() > cols) {
      throw std::invalid_argument(
          "colour_columns: block " + std::to_string(b) +
          (block.pattern == nullptr
               ? std::string(" has no pattern")
               : " (" + std::to_string(block.pattern->rows()) + " x " +
                     std::to_string(block.pattern->cols()) + " at (" + std::to_string(block.row0) +
                     ", " + std::to_string(block.col0) + ")) does not fit in a " +
                     std::to_string(rows) + " x " + std::to_string(cols) + " pattern"));
    }
  }
  Adjacency a;
  a.col_start.assign(cols + 1, 0);
  a.row_start.assign(rows + 1, 0);
  auto for_each_entry = [&blocks](auto&& visit) {
    for (const PatternBlock& block : blocks) {
      const SparseMatrix& P = *block.pattern;
      for (int j = 0; j < P.outerSize(); ++j) {
        for (SparseMatrix::InnerIterator it(P, j); it; ++it) {
          visit(block.row0 + static_cast<int>(it.row()), block.col0 + j);
        }
      }
    }
  };
  for_each_entry([&a](int row, int col) {
    ++a.col_start[col + 1];
    ++a.row_start[row + 1];
  });
  for (int j = 0; j < cols; ++j) a.col_start[j + 1] += a.col_start[j];
  for (int i = 0; i < rows; ++i) a.row_start[i + 1] += a.row_start[i];
  a.col_rows.resize(a.col_start[cols]);
  a.row_cols.resize(a.row_start[rows]);
  std::vector<int> col_fill(a.col_start.begin(), a.col_start.end() - 1);
  std::vector<int> row_fill(a.row_start.begin(), a.row_start.end() - 1);
  for_each_entry([&](int row, int col) {
    a.col_rows[col_fill[col]++] = row;
    a.row_cols[row_fill[row]++] = col;
  });
  return a;
}

}  // namespace

ColumnColouring colour_columns(int rows, int cols, const std::vector<PatternBlock>& blocks) {
  const Adjacency a = adjacency(rows, cols, blocks);
  ColumnColouring result;
  result.colour.assign(cols, -1);
  // forbidden[c] == j marks colour c as taken by a neighbour of column j; the
  // stamp saves clearing the array for every column.
  std::vector<int> forbidden;
  for (int j = 0; j < cols; ++j) {
    if (a.col_start[j] == a.col_start[j + 1]) continue;  // empty column: no colour
    for (int e = a.col_start[j]; e < a.col_start[j + 1]; ++e) {
      const int row = a.col_rows[e];
      for (int f = a.row_start[row]; f < a.row_start[row + 1]; ++f) {
        const int c = result.colour[a.row_cols[f]];
        if (c >= 0) forbidden[c] = j;
      }
    }
    int c = 0;
    while (c < result.colours && forbidden[c] == j) ++c;
    if (c == result.colours) {
      ++result.colours;
      forbidden.push_back(-1);
    }
    result.colour[j] = c;
  }
  return result;
}

ColumnColouring colour_columns(const SparseMatrix& pattern) {
  return colour_columns(static_cast<int>(pattern.rows()), static_cast<int>(pattern.cols()),
                        {PatternBlock{&pattern, 0, 0}});
}

bool is_valid_colouring(int rows, int cols, const std::vector<PatternBlock>& blocks,
                        const ColumnColouring& colouring) {
  if (static_cast<int>(colouring.colour.size()) != cols || colouring.colours < 0) return false;
  for (int c : colouring.colour) {
    if (c < -1 || c >= colouring.colours) return false;
  }
  const Adjacency a = adjacency(rows, cols, blocks);
  // Per colour, the last row that used it and the column that did (a column
  // repeated by overlapping blocks is no conflict with itself).
  std::vector<int> seen_row(colouring.colours, -1), seen_col(colouring.colours, -1);
  for (int i = 0; i < rows; ++i) {
    for (int f = a.row_start[i]; f < a.row_start[i + 1]; ++f) {
      const int col = a.row_cols[f];
      const int c = colouring.colour[col];
      if (c < 0) return false;  // a column with an entry must be differenced
      if (seen_row[c] == i && seen_col[c] != col) return false;
      seen_row[c] = i;
      seen_col[c] = col;
    }
  }
  return true;
}

}  // namespace stiffsim
