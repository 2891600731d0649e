#pragma once
// Uniform command-line behaviour for every executable: --help exits 0, a bad argument prints
// one line naming the value and what was expected and exits 2, anything else exits 1
// (errors.hpp). Only the executables' option parsing includes it.
#include "sphperf/errors.hpp"

#include <CLI/CLI.hpp>

#include <cmath>
#include <iostream>
#include <stdexcept>
#include <string>
#include <string_view>

namespace sphperf {

// Parses argv; on --help prints and requests exit 0, on a parse error throws UsageError.
inline void parse_cli(CLI::App &app, int argc, char **argv) {
    // --help shows every option's default: the values bound before parsing.
    for (auto *opt : app.get_options())
        opt->capture_default_str();
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp &) {
        std::cout << app.help();
        throw ExitRequest{0};
    } catch (const CLI::CallForAllHelp &) {
        std::cout << app.help("", CLI::AppFormatMode::All);
        throw ExitRequest{0};
    } catch (const CLI::ParseError &e) {
        std::string msg = e.what();
        for (auto &c : msg)
            if (c == '\n')
                c = ' ';
        throw UsageError(msg + " (see --help)");
    }
}

// CLI11's number validators let NaN and inf through: combine them with this one.
inline const CLI::Validator Finite(
    [](const std::string &s) {
        try {
            const double v = std::stod(s);
            return std::isfinite(v) ? std::string() : "value " + s + " is not a finite number";
        } catch (const std::exception &) {
            return "value " + s + " is not a number";
        }
    },
    "FINITE");

// A finite number above (or at least) a bound, with a one-line message naming the value.
inline CLI::Validator finite_above(double bound, bool or_equal) {
    const std::string want = std::string(or_equal ? ">= " : "> ") + CLI::detail::to_string(bound);
    return CLI::Validator(
        [bound, or_equal, want](const std::string &s) {
            try {
                const double v = std::stod(s);
                if (std::isfinite(v) && (or_equal ? v >= bound : v > bound))
                    return std::string();
            } catch (const std::exception &) {
            }
            return "value " + s + " is not a finite number " + want;
        },
        "FINITE " + want);
}
inline const CLI::Validator FinitePositive = finite_above(0.0, false);
inline const CLI::Validator FiniteNonNegative = finite_above(0.0, true);

} // namespace sphperf
