// libFuzzer harness: the checkpoint readers (a rank file, the record file, the manifest).
#include "fuzz_common.hpp"
#include "sphperf/sph/checkpoint.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
    using namespace sphperf;
    const std::string bytes(reinterpret_cast<const char *>(data), size);
    fuzz::refuses_or_reads([&] { (void)sph::deserialise_rank(bytes, "fuzz"); });
    fuzz::refuses_or_reads([&] { (void)sph::deserialise_record(bytes, "fuzz"); });
    const auto manifest = fuzz::scratch_file("manifest.json", data, size);
    fuzz::refuses_or_reads([&] { (void)sph::read_manifest(manifest.parent_path()); });
    return 0;
}
