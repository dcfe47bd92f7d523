# Included by ctest after the test lists that gtest_discover_tests wrote (tests/CMakeLists.txt): the tests that take
# longest, each with its time in seconds as its COST, so that ctest -j starts them first. A fresh tree has no timings
# of its own (ctest keeps them in Testing/Temporary/CTestCostData.txt after a run) and starts tests in the order they
# were declared; the 100 000-block test, declared late, then ran alone for the last 4 minutes of the plain suite.
# The figures are the larger of a plain and an ASan/UBSan run on 2 cores (docs/robustness.md); only their order
# matters. A name that is not built in a tree (scripts/test --sanitize thread builds two targets) is ignored.
set(ladder_slow_tests
  Blocks.AHundredThousandBlocksHoldAtOneMillisecond 270
  StiffChain.ProjectionRunsWhereShakeFails 53
  Blocks.FreeChainWhipsWithNoStepRedone 46
  RollingRipple.TheTallLaddersRippleRunsDownAllSixtyThreeHingesInOrder 39
  Threads.TwoThreadsTakeTheSameStepsAsOne 37
  Blocks.AWindowOfTheChainSolvesTheSameStepsAsWholePasses 30
  LongRun.TenMillionStepsOfTheDampedToy 30
  Midpoint.NoSecularEnergyTrendOnALongChain 28
  Server.AMillionCommandFloodLeavesMemoryBoundedAndOthersAnswered 27
  RollingRipple.TheLongLaddersRippleStopsAfterTwoHinges 26
  Blocks.TenThousandTippedAtOneMillisecond 26
  NetFault.ThousandCommandsUnderTwentyPercentLossAreEachAppliedOnce 25
  Blocks.AMillion 24
  AtTheLimit.AWhipThatCyclesEvenFromShorterStepsIsRescuedByMoreIterations 24
  TimeStep.OneMicrosecondAgreesWithTheDefault 20
  NetFault.ClientResumesAfterAPartitionLongerThanTheLease 19
  Midpoint.HangingChainModesMatchTheLinearisedChain 17
  Adaptive.AnUnmeetableToleranceCostsAtMostTheSmallestSubStepsAndAStopCutsBetweenThem 16
  Threads.AlgorithmOnesMeasureCountsTheHingeAtTheHalvesBoundary 15)
list(LENGTH ladder_slow_tests n)
math(EXPR last "${n} - 1")
foreach(i RANGE 0 ${last} 2)
  math(EXPR j "${i} + 1")
  list(GET ladder_slow_tests ${i} name)
  list(GET ladder_slow_tests ${j} seconds)
  set_tests_properties(${name} PROPERTIES COST ${seconds})
endforeach()
