#include "server/cluster/MpiRuntime.h"

#include "server/cluster/SortLast.h"

#include <cstdlib>
#include <string>

namespace bc::server::cluster {

MpiRuntime::MpiRuntime(int required) {
    int initialised = 0;
    MPI_Initialized(&initialised);
    if (initialised) throw ClusterError("MPI is already initialised in this process");
    int provided = MPI_THREAD_SINGLE;
    if (MPI_Init_thread(nullptr, nullptr, required, &provided) != MPI_SUCCESS)
        throw ClusterError("MPI_Init_thread failed");
    if (provided < required) {
        MPI_Finalize();
        throw ClusterError("the MPI library offers thread level " + std::to_string(provided) +
                           ", brickcast needs " + std::to_string(required));
    }
    // Errors come back as codes (SortLast checks each) instead of ending the job silently.
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    MPI_Comm_rank(MPI_COMM_WORLD, &mRank);
    MPI_Comm_size(MPI_COMM_WORLD, &mSize);
}

MpiRuntime::~MpiRuntime() {
    int finalised = 0;
    MPI_Finalized(&finalised);
    if (!finalised) MPI_Finalize();
}

void MpiRuntime::abortAll(int code) {
    MPI_Abort(MPI_COMM_WORLD, code);
    std::_Exit(code); // MPI_Abort does not return; if a library's did, end anyway
}

} // namespace bc::server::cluster
