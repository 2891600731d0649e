#pragma once
// Exit codes and the errors every executable maps onto them: bad input is one line and exit 2,
// anything else exit 1. Apart from cli.hpp so that a library reporting bad input does not
// compile CLI11 (about 5 s per translation unit on this project's 2-core VMs).
#include <iostream>
#include <stdexcept>
#include <string_view>

namespace sphperf {

inline constexpr int exit_usage = 2;
inline constexpr int exit_failure = 1;

// Bad input from the user: reported as one line, exit code 2.
class UsageError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

// Thrown to leave main early with a given code after the message was already printed.
struct ExitRequest {
    int code;
};

// Runs a program body and maps exceptions to exit codes with a one-line message on stderr.
template <class Body> int guarded_main(std::string_view program, Body &&body) {
    try {
        return body();
    } catch (const ExitRequest &e) {
        return e.code;
    } catch (const UsageError &e) {
        std::cerr << program << ": error: " << e.what() << '\n';
        return exit_usage;
    } catch (const std::exception &e) {
        std::cerr << program << ": fatal: " << e.what() << '\n';
        return exit_failure;
    }
}

} // namespace sphperf
