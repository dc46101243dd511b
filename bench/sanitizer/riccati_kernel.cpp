// The shape of pem's inner loop (src/estimation/pem.cpp): a 10-state Kalman
// filter's Riccati recursion and gain on fixed-size Eigen matrices, two
// outputs. bench/run_sanitizer_bench.sh builds it under each sanitizer flag
// set and prints the time against the uninstrumented build of the same run;
// it says what the sanitizer pass pays per check group, not how fast pem is.
#include <Eigen/Dense>

#include <chrono>
#include <cstdio>
#include <cstdlib>

int main(int argc, char** argv) {
  using Mat10 = Eigen::Matrix<double, 10, 10>;
  const int steps = argc > 1 ? std::atoi(argv[1]) : 200000;
  Mat10 a = 0.9 * Mat10::Identity();
  for (int i = 0; i + 1 < 10; ++i) a(i, i + 1) = 0.01 * (i + 1);
  const Mat10 q = 1e-3 * Mat10::Identity();
  Eigen::Matrix<double, 2, 10> c = Eigen::Matrix<double, 2, 10>::Zero();
  c(0, 0) = 1.0;
  c(1, 1) = 1.0;
  const Eigen::Matrix2d r = 1e-2 * Eigen::Matrix2d::Identity();
  Mat10 p = Mat10::Identity();
  double trace_sum = 0.0;  // printed, so the loop is not optimised away
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < steps; ++i) {
    p = a * p * a.transpose() + q;                                    // predict
    const Eigen::Matrix2d s = c * p * c.transpose() + r;              // innovation covariance
    const Eigen::Matrix<double, 10, 2> k = p * c.transpose() * s.inverse();
    p -= k * c * p;                                                   // update
    trace_sum += p.trace();
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%.6f %.6g\n", secs, trace_sum);
  return 0;
}
