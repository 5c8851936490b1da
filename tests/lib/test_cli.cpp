// SPDX-License-Identifier: LGPL-2.1-or-later
// The `lftag` tool as scripts use it: exit status, messages, files.
#include <cstdio>
#include <fstream>
#include <memory>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

namespace {

struct CliResult {
  int status;
  std::string output;  // stdout and stderr
};

CliResult run(const std::string& args) {
  const std::string cmd = std::string(LFTAG_CLI) + " " + args + " 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  std::string out;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe.get())) > 0) out.append(buf, n);
  const int status = pclose(pipe.release());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

const std::string kTmp = testing::TempDir();

}  // namespace

TEST(Cli, GenerateWritesEveryFormat) {
  for (const char* ext : {"svg", "pdf", "png"}) {
    const std::string out = kTmp + "/cli." + ext;
    std::remove(out.c_str());
    const CliResult r = run("generate --family 4x4 --id 0xabc --size 5cm --output " + out);
    EXPECT_EQ(r.status, 0) << r.output;
    EXPECT_TRUE(std::ifstream(out).good()) << out;
  }
  const CliResult sheet = run("generate --family 3x3 --id 0-29 --size 40mm --paper letter --output " + kTmp + "/sheet.pdf");
  EXPECT_EQ(sheet.status, 0) << sheet.output;
  EXPECT_NE(sheet.output.find("30 markers"), std::string::npos) << sheet.output;
}

TEST(Cli, GenerateRejectsBadInputWithAMessage) {
  CliResult r = run("generate --family 9x9 --id 1 --output " + kTmp + "/x.svg");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("unknown family '9x9'"), std::string::npos) << r.output;
  r = run("generate --family 3x3 --id 16384 --output " + kTmp + "/x.svg");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("out of range for family 3x3"), std::string::npos) << r.output;
  r = run("generate --family 3x3 --id 12 --output /nonexistent-dir/x.svg");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("cannot write '/nonexistent-dir/x.svg'"), std::string::npos) << r.output;
  r = run("generate --family 3x3 --id twelve --output " + kTmp + "/x.svg");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("not a decimal number"), std::string::npos) << r.output;
  r = run("generate --family 3x3 --id 1 --size 3furlongs --output " + kTmp + "/x.svg");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("unknown unit"), std::string::npos) << r.output;
  r = run("generate --family 3x3 --output " + kTmp + "/x.svg");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--id"), std::string::npos) << r.output;
}

TEST(Cli, RenderWritesImageAndTruth) {
  const std::string png = kTmp + "/scene.png";
  const CliResult r = run("render --family 8x8 --id 0x123456789abcdef0123456789abcdef --distance 3 --tilt 30 --noise 2 --output " + png);
  ASSERT_EQ(r.status, 0) << r.output;
  const cv::Mat image = cv::imread(png, cv::IMREAD_GRAYSCALE);
  EXPECT_EQ(image.cols, 640);
  EXPECT_EQ(image.rows, 480);
  std::ifstream in(kTmp + "/scene.json");
  const nlohmann::json truth = nlohmann::json::parse(in);
  ASSERT_EQ(truth["markers"].size(), 1u);
  const auto& m = truth["markers"][0];
  EXPECT_EQ(m["family"], "8x8");
  EXPECT_EQ(m["id"], "1512366075204170929049582354406559215");  // over 53 bits: a decimal string
  EXPECT_EQ(m["keypoints"].size(), 4u);
  EXPECT_EQ(m["centers"].size(), 64u);
  EXPECT_TRUE(m["fully_visible"].get<bool>());
}

TEST(Cli, RenderRejectsBadInput) {
  CliResult r = run("render --family 3x3 --id 99999 --output " + kTmp + "/x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("out of range"), std::string::npos) << r.output;
  r = run("render --calibration /nonexistent.yml --output " + kTmp + "/x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("/nonexistent.yml"), std::string::npos) << r.output;
  r = run("render --output /nonexistent-dir/x.png");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("cannot write"), std::string::npos) << r.output;
}

TEST(Cli, HelpDocumentsTheOptions) {
  const CliResult r = run("generate --help");
  EXPECT_EQ(r.status, 0);
  for (const char* opt : {"--family", "--id", "--size", "--margin", "--dpi", "--sheet", "--paper", "--output"})
    EXPECT_NE(r.output.find(opt), std::string::npos) << opt;
  const CliResult top = run("--help");
  EXPECT_NE(top.output.find("render"), std::string::npos);
  EXPECT_NE(run("").status, 0);
}
