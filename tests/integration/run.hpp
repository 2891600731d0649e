#pragma once
// Runs a command line through the shell and captures exit code, stdout and stderr.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

namespace sphperf::testing {

struct Run {
    int code = -1;
    std::string out, err;
    int err_lines() const {
        int n = 0;
        for (char c : err)
            n += c == '\n';
        return n;
    }
};

inline std::string slurp(const std::filesystem::path &p) {
    std::ifstream in(p);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

inline Run run(const std::string &cmd) {
    static int counter = 0;
    const auto base = std::filesystem::temp_directory_path() /
                      ("sphperf_run_" + std::to_string(getpid()) + "_" + std::to_string(counter++));
    const std::string full = cmd + " >" + base.string() + ".out 2>" + base.string() + ".err";
    const int status = std::system(full.c_str());
    Run r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(base.string() + ".out");
    r.err = slurp(base.string() + ".err");
    std::filesystem::remove(base.string() + ".out");
    std::filesystem::remove(base.string() + ".err");
    return r;
}

inline std::string bin(const std::string &name) {
    return std::string(SPHPERF_BIN_DIR) + "/" + name;
}
inline std::string mpirun(int ranks) {
    return "bash " + std::string(SPHPERF_SCRIPTS_DIR) + "/mpirun.sh -n " + std::to_string(ranks) +
           " ";
}

// Removes the scratch directories when the test program passed; after a failure it keeps them
// and names them, for whoever debugs it. (ctest runs each test in its own process, so a
// directory outlives exactly the test that wrote it; without this every run left ~150 behind.)
class ScratchCleaner : public ::testing::EmptyTestEventListener {
public:
    static ScratchCleaner &instance() {
        static ScratchCleaner *c = [] {
            auto *l = new ScratchCleaner; // the listener list owns it
            ::testing::UnitTest::GetInstance()->listeners().Append(l);
            return l;
        }();
        return *c;
    }
    void add(const std::filesystem::path &d) { dirs_.push_back(d); }
    void OnTestProgramEnd(const ::testing::UnitTest &unit) override {
        for (const auto &d : dirs_) {
            if (unit.Passed()) {
                std::error_code ec;
                std::filesystem::remove_all(d, ec);
            } else {
                std::fprintf(stderr, "kept scratch directory %s\n", d.c_str());
            }
        }
        dirs_.clear();
    }

private:
    std::vector<std::filesystem::path> dirs_;
};

// A fresh scratch directory per test, removed at the end if the program passed.
inline std::filesystem::path scratch(const std::string &name) {
    const auto d = std::filesystem::temp_directory_path() /
                   ("sphperf_test_" + name + "_" + std::to_string(getpid()));
    std::filesystem::remove_all(d);
    std::filesystem::create_directories(d);
    ScratchCleaner::instance().add(d);
    return d;
}

inline nlohmann::json load(const std::filesystem::path &p) {
    std::ifstream in(p);
    return nlohmann::json::parse(in);
}

// Every number under `j` is finite; every key ending in _s, _GBps or _gflops is positive, except
// under `fits_only` keys (fitted intercepts of single pieces may extrapolate below zero).
inline void expect_figures_sane(const nlohmann::json &j, const std::string &where = "",
                                bool positive = true) {
    if (j.is_object()) {
        for (const auto &[k, v] : j.items()) {
            const bool unit = k.ends_with("_s") || k.ends_with("_GBps") || k.ends_with("_gflops");
            if (positive && unit && v.is_number()) {
                EXPECT_GT(v.get<double>(), 0.0) << where << "/" << k;
            }
            expect_figures_sane(v, where + "/" + k,
                                positive && k != "pieces" && k != "single_line");
        }
    } else if (j.is_array()) {
        for (std::size_t i = 0; i < j.size(); ++i)
            expect_figures_sane(j[i], where + "/" + std::to_string(i), positive);
    } else if (j.is_number_float()) {
        EXPECT_TRUE(std::isfinite(j.get<double>())) << where;
    }
}

inline void expect_keys(const nlohmann::json &j, std::initializer_list<const char *> pointers) {
    for (const char *p : pointers)
        EXPECT_TRUE(j.contains(nlohmann::json::json_pointer(p))) << "missing " << p;
}

inline void expect_envelope(const nlohmann::json &j, const std::string &benchmark) {
    expect_keys(j, {"/schema", "/benchmark", "/git_commit", "/host", "/topology/cores",
                    "/topology/packages", "/build/flags", "/build/compiler", "/timestamp"});
    EXPECT_EQ(j.value("benchmark", ""), benchmark);
}

} // namespace sphperf::testing
