#include "stiffsim/linalg/sparse_pattern.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace stiffsim {
namespace {

using Mask = Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>;

// Structure of A as a dense mask, read through the raw compressed arrays so
// that the test does not lean on the code under test.
Mask mask_of(const SparseMatrix& A) {
  Mask mask = Mask::Constant(A.rows(), A.cols(), false);
  for (int j = 0; j < A.cols(); ++j) {
    for (int k = A.outerIndexPtr()[j]; k < A.outerIndexPtr()[j + 1]; ++k) {
      mask(A.innerIndexPtr()[k], j) = true;
    }
  }
  return mask;
}

void expect_well_formed(const SparseMatrix& A) {
  ASSERT_TRUE(A.isCompressed());
  for (int j = 0; j < A.cols(); ++j) {
    for (int k = A.outerIndexPtr()[j] + 1; k < A.outerIndexPtr()[j + 1]; ++k) {
      EXPECT_LT(A.innerIndexPtr()[k - 1], A.innerIndexPtr()[k])
          << "rows must be strictly increasing in column " << j;
    }
  }
}

SparseMatrix from_dense(const Eigen::MatrixXd& dense) {
  std::vector<Eigen::Triplet<double>> triplets;
  for (int j = 0; j < dense.cols(); ++j) {
    for (int i = 0; i < dense.rows(); ++i) {
      if (dense(i, j) != 0.0) triplets.emplace_back(i, j, dense(i, j));
    }
  }
  SparseMatrix A(dense.rows(), dense.cols());
  A.setFromTriplets(triplets.begin(), triplets.end());
  A.makeCompressed();
  return A;
}

TEST(PatternBuilderTest, BuildMergesDuplicatesSortsRowsAndStoresExplicitZeros) {
  PatternBuilder builder(7, 6);
  Mask expected = Mask::Constant(7, 6, false);
  auto add = [&](int i, int j) {
    builder.add(i, j);
    expected(i, j) = true;
  };
  // Unsorted, with duplicates, so that sorting and merging are exercised.
  add(5, 2);
  add(0, 2);
  add(5, 2);
  add(3, 0);
  add(6, 5);
  add(0, 2);
  builder.add_block(1, 3, 2, 3);  // rows 1..2, cols 3..5
  for (int i = 1; i < 3; ++i) {
    for (int j = 3; j < 6; ++j) expected(i, j) = true;
  }
  builder.add_diagonal(2, 4);  // (2,2) .. (5,5)
  for (int k = 2; k < 6; ++k) expected(k, k) = true;
  Eigen::MatrixXd small(2, 2);
  small << 1, 0, 0, 2;  // diagonal 2x2 shifted to (4, 0)
  builder.add_pattern(from_dense(small), 4, 0);
  expected(4, 0) = expected(5, 1) = true;

  const SparseMatrix A = builder.build();
  expect_well_formed(A);
  EXPECT_EQ(A.rows(), 7);
  EXPECT_EQ(A.cols(), 6);
  EXPECT_EQ(mask_of(A), expected);
  EXPECT_EQ(A.nonZeros(), expected.count());
  for (int k = 0; k < A.nonZeros(); ++k) EXPECT_EQ(A.valuePtr()[k], 0.0);
}

TEST(PatternBuilderTest, EmptyColumnsAndEmptyPatternAreValid) {
  PatternBuilder builder(4, 5);
  builder.add(3, 4);
  const SparseMatrix A = builder.build();
  expect_well_formed(A);
  EXPECT_EQ(A.nonZeros(), 1);
  EXPECT_EQ(A.outerIndexPtr()[4], 0);
  EXPECT_EQ(A.outerIndexPtr()[5], 1);

  const SparseMatrix empty = PatternBuilder(3, 3).build();
  EXPECT_EQ(empty.nonZeros(), 0);
  EXPECT_TRUE(empty.isCompressed());
}

TEST(PatternBuilderTest, RejectsEntriesOutsideTheMatrix) {
  PatternBuilder builder(3, 4);
  EXPECT_THROW(builder.add(3, 0), std::out_of_range);
  EXPECT_THROW(builder.add(0, 4), std::out_of_range);
  EXPECT_THROW(builder.add(-1, 0), std::out_of_range);
  EXPECT_THROW(builder.add_block(2, 2, 2, 1), std::out_of_range);
}

TEST(ExpandBlocksTest, EqualsTheBuilderOfEveryBlock) {
  // A random block pattern with empty block columns, expanded, against the
  // same blocks added one entry at a time.
  std::mt19937 rng(11);
  std::bernoulli_distribution keep(0.35);
  const int block_rows = 6, block_cols = 5, b = 3;
  PatternBuilder blocks(block_rows, block_cols), entries(b * block_rows, b * block_cols);
  for (int J = 0; J < block_cols; ++J) {
    if (J == 2) continue;  // an empty block column
    for (int I = block_rows - 1; I >= 0; --I) {
      if (!keep(rng)) continue;
      blocks.add(I, J);
      entries.add_block(b * I, b * J, b, b);
    }
  }
  const SparseMatrix expanded = expand_blocks(blocks.build(), b);
  const SparseMatrix expected = entries.build();
  expect_well_formed(expanded);
  EXPECT_EQ(expanded.rows(), expected.rows());
  EXPECT_EQ(expanded.cols(), expected.cols());
  ASSERT_EQ(expanded.nonZeros(), expected.nonZeros());
  EXPECT_GT(expanded.nonZeros(), 0);
  for (int j = 0; j <= expected.cols(); ++j) {
    EXPECT_EQ(expanded.outerIndexPtr()[j], expected.outerIndexPtr()[j]) << "column " << j;
  }
  for (int k = 0; k < expected.nonZeros(); ++k) {
    EXPECT_EQ(expanded.innerIndexPtr()[k], expected.innerIndexPtr()[k]) << "slot " << k;
    EXPECT_EQ(expanded.valuePtr()[k], 0.0);
  }
  EXPECT_EQ(expand_blocks(PatternBuilder(2, 2).build(), 4).nonZeros(), 0);
  EXPECT_THROW(expand_blocks(blocks.build(), 0), std::invalid_argument);
}

TEST(SlotOfTest, FindsEveryEntryAndRejectsMissingOnes) {
  std::mt19937 rng(7);
  std::bernoulli_distribution keep(0.3);
  PatternBuilder builder(9, 8);
  Mask mask = Mask::Constant(9, 8, false);
  for (int j = 0; j < 8; ++j) {
    for (int i = 0; i < 9; ++i) {
      if (keep(rng)) {
        builder.add(i, j);
        mask(i, j) = true;
      }
    }
  }
  const SparseMatrix A = builder.build();
  for (int j = 0; j < 8; ++j) {
    for (int i = 0; i < 9; ++i) {
      if (mask(i, j)) {
        const int slot = slot_of(A, i, j);
        EXPECT_EQ(A.innerIndexPtr()[slot], i);
        EXPECT_GE(slot, A.outerIndexPtr()[j]);
        EXPECT_LT(slot, A.outerIndexPtr()[j + 1]);
      } else {
        EXPECT_THROW(slot_of(A, i, j), std::out_of_range) << "(" << i << ", " << j << ")";
      }
    }
  }
  EXPECT_THROW(slot_of(A, 9, 0), std::out_of_range);
  EXPECT_THROW(slot_of(A, 0, -1), std::out_of_range);
}

TEST(ScatterAddTest, AccumulatesShiftedPartsLikeDenseBlockAddition) {
  // whole: two overlapping 4x4 dense blocks plus the diagonal of a 10x10.
  PatternBuilder builder(10, 10);
  builder.add_block(1, 2, 4, 4);
  builder.add_block(4, 5, 4, 4);
  builder.add_diagonal(0, 10);
  SparseMatrix whole = builder.build();
  const Eigen::Index whole_nonzeros = whole.nonZeros();

  Eigen::MatrixXd part1(3, 4);
  part1 << 1, 0, 2, 0,  //
      0, 3, 0, 4,       //
      5, 0, 0, 6;
  Eigen::MatrixXd part2(4, 3);
  part2 << 0, 7, 0,  //
      8, 0, 0,       //
      0, 0, 9,       //
      10, 0, 11;
  const SparseMatrix sparse1 = from_dense(part1);
  const SparseMatrix sparse2 = from_dense(part2);
  const std::vector<int> slots1 = slots_in(whole, sparse1, 1, 2);
  const std::vector<int> slots2 = slots_in(whole, sparse2, 4, 5);
  ASSERT_EQ(slots1.size(), static_cast<std::size_t>(sparse1.nonZeros()));
  ASSERT_EQ(slots2.size(), static_cast<std::size_t>(sparse2.nonZeros()));

  Eigen::MatrixXd expected = Eigen::MatrixXd::Zero(10, 10);
  scatter_add(sparse1, slots1, 2.0, &whole);
  expected.block(1, 2, 3, 4) += 2.0 * part1;
  scatter_add(sparse2, slots2, -0.5, &whole);
  expected.block(4, 5, 4, 3) += -0.5 * part2;
  scatter_add(sparse1, slots1, 1.0, &whole);  // accumulates, does not overwrite
  expected.block(1, 2, 3, 4) += part1;

  EXPECT_EQ(whole.nonZeros(), whole_nonzeros) << "scatter_add must keep the pattern";
  EXPECT_TRUE(Eigen::MatrixXd(whole).isApprox(expected, 0.0)) << Eigen::MatrixXd(whole);

  set_zero_keep_pattern(&whole);
  EXPECT_EQ(whole.nonZeros(), whole_nonzeros);
  EXPECT_TRUE(Eigen::MatrixXd(whole).isZero(0.0));
}

TEST(SlotsInTest, RejectsPartsOutsideTheWholePattern) {
  PatternBuilder builder(6, 6);
  builder.add_block(0, 0, 3, 3);
  const SparseMatrix whole = builder.build();
  Eigen::MatrixXd part = Eigen::MatrixXd::Zero(2, 2);
  part(1, 1) = 1.0;  // lands at (3, 3) with shift (2, 2): not in the pattern
  try {
    slots_in(whole, from_dense(part), 2, 2);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("(3, 3)"), std::string::npos) << error.what();
    EXPECT_NE(std::string(error.what()).find("missing"), std::string::npos) << error.what();
  }
  EXPECT_NO_THROW(slots_in(whole, from_dense(part), 1, 1));
  EXPECT_THROW(slots_in(whole, from_dense(part), 5, 0), std::invalid_argument);
}

TEST(ScatterAddTest, RejectsSlotCountMismatch) {
  SparseMatrix whole = PatternBuilder(2, 2).build();
  Eigen::MatrixXd part = Eigen::MatrixXd::Identity(2, 2);
  EXPECT_THROW(scatter_add(from_dense(part), {0}, 1.0, &whole), std::invalid_argument);
}

TEST(StructuralSymmetryTest, ComparesPatternsNotValues) {
  PatternBuilder builder(5, 5);
  builder.add_diagonal(0, 5);
  builder.add(0, 3);
  builder.add(3, 0);
  SparseMatrix symmetric = builder.build();
  symmetric.coeffRef(0, 3) = 1.0;  // values differ: structure still symmetric
  EXPECT_TRUE(is_structurally_symmetric(symmetric));

  builder.add(4, 1);
  EXPECT_FALSE(is_structurally_symmetric(builder.build()));
  EXPECT_FALSE(is_structurally_symmetric(PatternBuilder(2, 3).build()));
}

// same_pattern and holds_pattern decide whether a set-up may take one
// pattern as the union of several (VelocityImplicitEuler's Newton matrix):
// checked here against the builder's union and against dense masks.
TEST(SamePatternTest, ComparesPositionsNotValues) {
  PatternBuilder builder(4, 4);
  builder.add(0, 0);
  builder.add(2, 1);
  builder.add(3, 3);
  SparseMatrix a = builder.build();
  SparseMatrix b = builder.build();
  b.coeffRef(2, 1) = 5.0;  // values differ: the pattern is the same
  EXPECT_TRUE(same_pattern(a, b));

  builder.add(1, 2);
  EXPECT_FALSE(same_pattern(a, builder.build()));  // one entry more
  PatternBuilder moved(4, 4);                      // as many entries, one of them elsewhere
  moved.add(0, 0);
  moved.add(1, 1);
  moved.add(3, 3);
  EXPECT_FALSE(same_pattern(a, moved.build()));
  EXPECT_FALSE(same_pattern(a, PatternBuilder(4, 5).build()));
  SparseMatrix uncompressed = a;
  uncompressed.uncompress();
  EXPECT_FALSE(same_pattern(a, uncompressed));
}

TEST(HoldsPatternTest, AgreesWithTheBuildersUnionOnRandomPatterns) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> index(0, 11);
  std::bernoulli_distribution coin(0.5);
  int unions = 0;
  for (int trial = 0; trial < 200; ++trial) {
    PatternBuilder whole_builder(12, 12), part_builder(12, 12);
    std::vector<std::pair<int, int>> added;
    for (int k = 0; k < 40; ++k) {
      added.emplace_back(index(rng), index(rng));
      whole_builder.add(added.back().first, added.back().second);
    }
    // Half of the parts are drawn from the whole's own entries (a subset
    // but for the diagonal), the others anywhere (rarely a subset).
    const bool from_whole = coin(rng);
    std::uniform_int_distribution<int> pick(0, static_cast<int>(added.size()) - 1);
    for (int k = 0; k < 6; ++k) {
      if (from_whole) {
        const auto [row, col] = added[pick(rng)];
        part_builder.add(row, col);
      } else {
        part_builder.add(index(rng), index(rng));
      }
    }
    if (coin(rng)) part_builder.add(index(rng), index(rng));  // maybe outside
    if (coin(rng)) whole_builder.add_diagonal(0, 12);
    const SparseMatrix whole = whole_builder.build(), part = part_builder.build();
    const Mask w = mask_of(whole), p = mask_of(part);
    const bool expected_part = (p.array() <= w.array()).all();
    const bool expected_diagonal = w.diagonal().all();
    EXPECT_EQ(holds_pattern(whole, part, false), expected_part) << "trial " << trial;
    EXPECT_EQ(holds_pattern(whole, part, true), expected_part && expected_diagonal)
        << "trial " << trial;
    // Where the whole holds both, it is their union, position for position.
    if (expected_part && expected_diagonal) {
      PatternBuilder union_builder(12, 12);
      union_builder.add_pattern(whole);
      union_builder.add_pattern(part);
      union_builder.add_diagonal(0, 12);
      EXPECT_TRUE(same_pattern(whole, union_builder.build())) << "trial " << trial;
      ++unions;
    }
  }
  EXPECT_GE(unions, 20);  // the union case was exercised, not only refusals
  EXPECT_FALSE(holds_pattern(PatternBuilder(3, 3).build(), PatternBuilder(4, 4).build(), false));
  EXPECT_FALSE(holds_pattern(PatternBuilder(3, 4).build(), PatternBuilder(3, 4).build(), true));
}

}  // namespace
}  // namespace stiffsim
