// Greedy distance-2 column colouring: valid on any pattern, optimal on the
// patterns whose count is known (diagonal 1, tridiagonal 3, dense n).

#include "stiffsim/linalg/column_colouring.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <stdexcept>

namespace stiffsim {
namespace {

SparseMatrix random_pattern(int rows, int cols, double density, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  PatternBuilder builder(rows, cols);
  for (int j = 0; j < cols; ++j) {
    for (int i = 0; i < rows; ++i) {
      if (uniform(rng) < density) builder.add(i, j);
    }
  }
  return builder.build();
}

SparseMatrix banded(int n, int half_bandwidth) {
  PatternBuilder builder(n, n);
  for (int j = 0; j < n; ++j) {
    for (int i = std::max(0, j - half_bandwidth); i <= std::min(n - 1, j + half_bandwidth); ++i)
      builder.add(i, j);
  }
  return builder.build();
}

// The definition, checked pair by pair (independent of is_valid_colouring).
bool same_colour_columns_share_no_row(const SparseMatrix& P, const ColumnColouring& colouring) {
  // build() stores explicit zeros, so the stored structure is compared, not values.
  for (int j = 0; j < P.cols(); ++j) {
    for (int k = j + 1; k < P.cols(); ++k) {
      if (colouring.colour[j] != colouring.colour[k] || colouring.colour[j] < 0) continue;
      for (SparseMatrix::InnerIterator a(P, j); a; ++a) {
        for (SparseMatrix::InnerIterator b(P, k); b; ++b) {
          if (a.row() == b.row()) return false;
        }
      }
    }
  }
  return true;
}

TEST(ColumnColouring, RandomPatternsGetValidColourings) {
  for (unsigned seed = 1; seed <= 20; ++seed) {
    const int rows = 5 + static_cast<int>(seed * 7 % 40), cols = 5 + static_cast<int>(seed % 30);
    const SparseMatrix P = random_pattern(rows, cols, 0.1 + 0.02 * (seed % 5), seed);
    const ColumnColouring colouring = colour_columns(P);
    ASSERT_EQ(static_cast<int>(colouring.colour.size()), cols);
    EXPECT_TRUE(same_colour_columns_share_no_row(P, colouring)) << "seed " << seed;
    EXPECT_TRUE(is_valid_colouring(rows, cols, {PatternBlock{&P}}, colouring));
    for (int j = 0; j < cols; ++j) {
      const bool empty = P.col(j).nonZeros() == 0;
      EXPECT_EQ(colouring.colour[j] < 0, empty) << "column " << j;
    }
    EXPECT_LE(colouring.colours, cols);
  }
}

TEST(ColumnColouring, DiagonalNeedsOneColour) {
  const SparseMatrix P = banded(50, 0);
  const ColumnColouring colouring = colour_columns(P);
  EXPECT_EQ(colouring.colours, 1);
  EXPECT_TRUE(
      std::all_of(colouring.colour.begin(), colouring.colour.end(), [](int c) { return c == 0; }));
}

TEST(ColumnColouring, TridiagonalNeedsThreeColours) {
  const SparseMatrix P = banded(50, 1);
  const ColumnColouring colouring = colour_columns(P);
  EXPECT_EQ(colouring.colours, 3);
  for (int j = 0; j < 50; ++j) EXPECT_EQ(colouring.colour[j], j % 3);
}

TEST(ColumnColouring, BandwidthSetsTheCountNotTheSize) {
  // Every row of a band of half-width w holds 2w + 1 columns: a lower bound
  // the greedy order meets whatever n.
  for (int n : {20, 200, 2000}) {
    EXPECT_EQ(colour_columns(banded(n, 2)).colours, 5) << n;
  }
}

TEST(ColumnColouring, DenseNeedsOneColourPerColumn) {
  PatternBuilder builder(4, 6);
  builder.add_block(0, 0, 4, 6);
  EXPECT_EQ(colour_columns(builder.build()).colours, 6);
}

TEST(ColumnColouring, EmptyColumnsAndEmptyPatternsCostNothing) {
  PatternBuilder builder(3, 4);
  builder.add(0, 0);
  builder.add(2, 3);
  const ColumnColouring some = colour_columns(builder.build());
  EXPECT_EQ(some.colours, 1);
  EXPECT_EQ(some.colour, (std::vector<int>{0, -1, -1, 0}));

  const SparseMatrix none(0, 0);
  const ColumnColouring nothing = colour_columns(none);
  EXPECT_EQ(nothing.colours, 0);
  EXPECT_TRUE(nothing.colour.empty());
}

TEST(ColumnColouring, StackedBlocksColourTheWholeMatrix) {
  // [K D; 0 0] over x = (q, v) with K = D tridiagonal: q_j and v_j share
  // rows, so the stacked pattern needs twice the colours of one block.
  const int n = 30;
  const SparseMatrix T = banded(n, 1);
  const SparseMatrix empty_rows(0, n);
  const std::vector<PatternBlock> blocks = {{&T, 0, 0}, {&T, 0, n}, {&empty_rows, n, 0}};
  const ColumnColouring colouring = colour_columns(n, 2 * n, blocks);
  EXPECT_EQ(colouring.colours, 6);
  EXPECT_TRUE(is_valid_colouring(n, 2 * n, blocks, colouring));

  // A lower row block coupling v only to itself (diagonal) changes nothing in
  // the q columns.
  const SparseMatrix I = banded(n, 0);
  const std::vector<PatternBlock> with_z = {{&T, 0, 0}, {&T, 0, n}, {&I, n, n}};
  const ColumnColouring z_colouring = colour_columns(2 * n, 2 * n, with_z);
  EXPECT_TRUE(is_valid_colouring(2 * n, 2 * n, with_z, z_colouring));
  EXPECT_EQ(z_colouring.colours, 6);
}

TEST(ColumnColouring, ValidityCheckRejectsConflicts) {
  const SparseMatrix T = banded(5, 1);
  ColumnColouring bad = colour_columns(T);
  bad.colour[1] = bad.colour[0];
  EXPECT_FALSE(is_valid_colouring(5, 5, {PatternBlock{&T}}, bad));
  ColumnColouring uncoloured = colour_columns(T);
  uncoloured.colour[2] = -1;
  EXPECT_FALSE(is_valid_colouring(5, 5, {PatternBlock{&T}}, uncoloured));
}

TEST(ColumnColouring, RejectsBlocksOutsideTheWhole) {
  const SparseMatrix T = banded(5, 1);
  EXPECT_THROW(colour_columns(5, 5, {PatternBlock{&T, 1, 0}}), std::invalid_argument);
  EXPECT_THROW(colour_columns(5, 5, {PatternBlock{nullptr, 0, 0}}), std::invalid_argument);
}

}  // namespace
}  // namespace stiffsim
